//! The laser scan simulator (paper sect. 7.2.1) and the adaptive robot, cleverRobot (sect. 7.2.2).
