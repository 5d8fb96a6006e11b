//! Mesh statistics for `surfsynth mesh-info` (helper fills this in).
