//! File formats: scan JSON Lines (CSM's laser_data layout), `.wall` floor plans, CARMEN logs
//! and TUM trajectories. Every reader reports bad input as `FILE:LINE: what is wrong`.
