//! Bangay & Morkel 2006: the √2 subdivision hierarchy, the sweep order and
//! diffused orientation field, graph matching of vertex neighbourhoods, and the
//! graph-cut transfer (with its max-flow solver) that joins copied regions.

pub mod diffuse_orientation;
pub mod graph_cut_transfer;
pub mod graph_match;
pub mod max_flow;
pub mod sqrt2;
pub mod sweep;
