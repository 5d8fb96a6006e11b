//! Procedural meshes (helper fills this in).
