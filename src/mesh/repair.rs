//! Load-time repairs (helper fills this in).
