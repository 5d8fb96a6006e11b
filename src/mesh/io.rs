//! Mesh loaders and writers (helper fills this in).
