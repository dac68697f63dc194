//! Scan matching (paper sect. 2.2 and 8.2): ICP point-to-point and point-to-line, pairwise and
//! against a growing map (metascan).
