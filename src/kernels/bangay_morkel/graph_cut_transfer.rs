//! Graph-cut texture transfer onto a surface region (Bangay & Morkel 2006
//! §3.4, Fig. 9, eq. 1; after Kwatra et al. 2003), solved with the
//! Boykov–Kolmogorov max-flow of [`crate::kernels::bangay_morkel::max_flow`].

use crate::kernels::bangay_morkel::max_flow::FlowGraph;

/// A surface region whose vertices could take colours from the matched
/// exemplar neighbourhood. Vertices are numbered `0..n` locally; colours
/// hold `channels` values per vertex.
#[derive(Clone, Copy, Debug)]
pub struct TransferRegion<'a> {
    /// Values per colour.
    pub channels: usize,
    /// Mesh edges between region vertices (local ids).
    pub edges: &'a [[u32; 2]],
    /// Current surface colour `C_s` of each vertex (ignored where not
    /// `coloured`).
    pub surface: &'a [f32],
    /// Colour `C_t` the exemplar imprint would give each vertex.
    pub texture: &'a [f32],
    /// Whether each vertex has a surface colour yet.
    pub coloured: &'a [bool],
    /// Whether each vertex lies on the region's border (the outermost ring
    /// of the k-region).
    pub border: &'a [bool],
    /// Distance of each vertex from the target vertex in texture space,
    /// texels (`x_A` of eq. 1).
    pub distance: &'a [f32],
    /// The matched (target) vertex.
    pub target: u32,
    /// `r` of eq. 1: the diameter of the texture neighbourhood, texels.
    pub diameter: f32,
    /// Per edge of `edges`, a factor on its weight: its length in texels
    /// makes the cut's cost the seam's length times the mismatch along it,
    /// whatever the mesh density (Boykov & Kolmogorov 2003's geo-cuts);
    /// empty = 1 for every edge (eq. 1 as printed).
    pub edge_factor: &'a [f32],
}

/// Which vertices take the texture, and the seam.
#[derive(Clone, Debug, PartialEq)]
pub struct TransferCut {
    /// Per local vertex: true when it takes the exemplar colour (texture
    /// side of the cut), false when it keeps its surface colour.
    pub take_texture: Vec<bool>,
    /// Capacity of the minimum cut: the seam cost, in the units of eq. 1
    /// (colour distance).
    pub cost: f64,
    /// The maximum flow; equal to `cost` up to rounding.
    pub flow: f64,
}

impl TransferCut {
    /// Number of vertices that take the texture.
    pub fn taken(&self) -> usize {
        self.take_texture.iter().filter(|&&t| t).count()
    }
}

/// The minimum cut of the transfer graph of Bangay & Morkel §3.4 (Fig. 9).
///
/// One node per region vertex and two terminals, *texture* (the flow
/// source) and *surface* (the sink):
/// * the target vertex must receive the exemplar colour: tied to the
///   texture terminal with infinite weight;
/// * border vertices that are already coloured keep their colour: tied to
///   the surface terminal with infinite weight;
/// * vertices without a colour have nothing to keep, so they take the
///   exemplar colour too (tied to the texture terminal; the transfer's
///   purpose is to colour several vertices per match);
/// * each mesh edge `A–B` gets eq. 1,
///   `W(A, B) = M(A, B) · exp(−(x_A² + x_B²) / (σ r²))`, with
///   `M(A, B) = |C_s(A) − C_t(A)| + |C_s(B) − C_t(B)|` (Euclidean colour
///   distances; 0 for a vertex without a colour). The weight falls with
///   the distance from the target, which moves the seam away from it.
///
/// Preconditions: slices sized as documented on [`TransferRegion`];
/// `target < n`; `sigma > 0`; `diameter > 0`.
pub fn graph_cut_transfer(region: &TransferRegion, sigma: f32) -> TransferCut {
    let n = region.coloured.len();
    let ch = region.channels;
    let mismatch: Vec<f64> = (0..n)
        .map(|v| {
            if !region.coloured[v] {
                return 0.0;
            }
            let s = &region.surface[v * ch..(v + 1) * ch];
            let t = &region.texture[v * ch..(v + 1) * ch];
            s.iter()
                .zip(t)
                .map(|(a, b)| ((a - b) as f64).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .collect();
    let denom = sigma as f64 * (region.diameter as f64).powi(2);
    let mut g = FlowGraph::with_capacity(n, region.edges.len());
    for (e, &[a, b]) in region.edges.iter().enumerate() {
        let factor = region.edge_factor.get(e).map_or(1.0, |&f| f as f64);
        let (xa, xb) = (
            region.distance[a as usize] as f64,
            region.distance[b as usize] as f64,
        );
        let w = factor
            * (mismatch[a as usize] + mismatch[b as usize])
            * (-(xa * xa + xb * xb) / denom).exp();
        g.add_edge(a, b, w, w);
    }
    for v in 0..n {
        if v as u32 == region.target || !region.coloured[v] {
            g.add_terminal_weights(v as u32, f64::INFINITY, 0.0);
        } else if region.border[v] {
            g.add_terminal_weights(v as u32, 0.0, f64::INFINITY);
        }
    }
    let flow = g.max_flow();
    let take_texture = (0..n as u32).map(|v| g.in_source_segment(v)).collect();
    TransferCut {
        take_texture,
        cost: g.cut_value(),
        flow,
    }
}
