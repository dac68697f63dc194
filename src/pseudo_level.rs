//! Pseudo-level scans (paper sect. 6): one scan projected onto the level plane, wall points only.
