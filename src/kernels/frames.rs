//! Tangent frames (s, t, n) per vertex.
