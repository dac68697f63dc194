//! Level estimation (paper sect. 5): wall polygons, the up vector, attitude and failure detection.
