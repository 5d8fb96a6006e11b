//! Boykov–Kolmogorov max-flow kernel (`surfsynth::kernels::bangay_morkel::max_flow`)
//! against `petgraph::algo::dinics` as an oracle, plus hand-made cases.
//!
//! Every solved graph is checked three ways: the flow equals the oracle's,
//! the cut recomputed here from the segmentation equals the flow (so the
//! segmentation is a minimum cut), and `FlowGraph::cut_value` agrees.

use petgraph::Graph;
use petgraph::algo::dinics;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use surfsynth::kernels::bangay_morkel::max_flow::FlowGraph;

/// A flow problem as plain lists, so it can be fed to both solvers.
#[derive(Clone, Debug, Default)]
struct Spec {
    nodes: usize,
    /// (a, b, cap a→b, cap b→a)
    edges: Vec<(u32, u32, f64, f64)>,
    /// (node, source cap, sink cap); a node may appear several times.
    tlinks: Vec<(u32, f64, f64)>,
}

impl Spec {
    fn build(&self) -> FlowGraph {
        let mut g = FlowGraph::with_capacity(self.nodes, self.edges.len());
        for &(a, b, cab, cba) in &self.edges {
            g.add_edge(a, b, cab, cba);
        }
        for &(v, s, t) in &self.tlinks {
            g.add_terminal_weights(v, s, t);
        }
        g
    }

    /// Max flow by petgraph's Dinic on an explicit directed graph: nodes
    /// `0..n`, source `n`, sink `n + 1`; both directions of every edge.
    fn dinics_flow(&self) -> f64 {
        let mut pg = Graph::<(), f64>::with_capacity(self.nodes + 2, 0);
        let ids: Vec<_> = (0..self.nodes + 2).map(|_| pg.add_node(())).collect();
        let (s, t) = (ids[self.nodes], ids[self.nodes + 1]);
        for &(a, b, cab, cba) in &self.edges {
            if a == b {
                continue;
            }
            pg.add_edge(ids[a as usize], ids[b as usize], cab);
            pg.add_edge(ids[b as usize], ids[a as usize], cba);
        }
        for &(v, sc, tc) in &self.tlinks {
            pg.add_edge(s, ids[v as usize], sc);
            pg.add_edge(ids[v as usize], t, tc);
        }
        dinics(&pg, s, t).0
    }

    /// Capacity of the cut `segment` (true = source side), from the spec.
    fn cut_of(&self, segment: &[bool]) -> f64 {
        let mut cut = 0.0;
        for &(v, s, t) in &self.tlinks {
            cut += if segment[v as usize] { t } else { s };
        }
        for &(a, b, cab, cba) in &self.edges {
            match (segment[a as usize], segment[b as usize]) {
                (true, false) => cut += cab,
                (false, true) => cut += cba,
                _ => {}
            }
        }
        cut
    }

    /// Total source and sink t-link capacity per node.
    fn terminal_totals(&self) -> Vec<(f64, f64)> {
        let mut tot = vec![(0.0, 0.0); self.nodes];
        for &(v, s, t) in &self.tlinks {
            tot[v as usize].0 += s;
            tot[v as usize].1 += t;
        }
        tot
    }
}

fn close(a: f64, b: f64) -> bool {
    a == b || (a - b).abs() <= 1e-6 * a.abs().max(b.abs()) + 1e-9
}

/// Solves `spec` with BK and checks it against Dinic and the cut, returning
/// the flow and the segmentation.
fn check(spec: &Spec, what: &str) -> (f64, Vec<bool>) {
    let mut g = spec.build();
    let flow = g.max_flow();
    let oracle = spec.dinics_flow();
    assert!(
        close(flow, oracle),
        "{what}: BK flow {flow} != dinics {oracle}"
    );
    let segment: Vec<bool> = (0..spec.nodes as u32)
        .map(|v| g.in_source_segment(v))
        .collect();
    let cut = spec.cut_of(&segment);
    assert!(
        close(cut, flow),
        "{what}: cut of the segmentation {cut} != flow {flow}"
    );
    assert!(
        close(g.cut_value(), flow),
        "{what}: cut_value {} != flow {flow}",
        g.cut_value()
    );
    for (v, &(s, t)) in spec.terminal_totals().iter().enumerate() {
        if s == f64::INFINITY {
            assert!(segment[v], "{what}: node {v} has an infinite source t-link");
        }
        if t == f64::INFINITY {
            assert!(!segment[v], "{what}: node {v} has an infinite sink t-link");
        }
    }
    (flow, segment)
}

fn random_capacity(rng: &mut Pcg64, integer: bool) -> f64 {
    if rng.random_bool(0.15) {
        0.0
    } else if integer {
        f64::from(rng.random_range(1..20u32))
    } else {
        rng.random_range(0.001..10.0)
    }
}

fn random_spec(seed: u64) -> Spec {
    let mut rng = Pcg64::seed_from_u64(seed);
    let nodes = rng.random_range(2..200usize);
    let integer = rng.random_bool(0.3);
    let mean_degree = rng.random_range(0.5..12.0);
    let num_edges = (nodes as f64 * mean_degree / 2.0) as usize;
    let mut spec = Spec {
        nodes,
        ..Spec::default()
    };
    for _ in 0..num_edges {
        let a = rng.random_range(0..nodes as u32);
        let mut b = rng.random_range(0..nodes as u32 - 1);
        if b >= a {
            b += 1;
        }
        let cab = random_capacity(&mut rng, integer);
        let cba = match rng.random_range(0..3) {
            0 => cab,
            1 => 0.0,
            _ => random_capacity(&mut rng, integer),
        };
        spec.edges.push((a, b, cab, cba));
    }
    let hard_prob = if rng.random_bool(0.5) { 0.04 } else { 0.0 };
    for v in 0..nodes as u32 {
        let r: f64 = rng.random();
        let (mut s, mut t) = (0.0, 0.0);
        if r < 0.2 {
            s = random_capacity(&mut rng, integer);
        } else if r < 0.4 {
            t = random_capacity(&mut rng, integer);
        } else if r < 0.55 {
            s = random_capacity(&mut rng, integer);
            t = random_capacity(&mut rng, integer);
        }
        let h: f64 = rng.random();
        if h < hard_prob {
            s = f64::INFINITY;
        } else if h < 2.0 * hard_prob {
            t = f64::INFINITY;
        }
        if s > 0.0 || t > 0.0 {
            spec.tlinks.push((v, s, t));
        }
        // Some nodes get a second, cumulative t-link.
        if rng.random_bool(0.05) {
            spec.tlinks
                .push((v, random_capacity(&mut rng, integer), 0.0));
        }
    }
    spec
}

#[test]
fn random_graphs_match_dinics() {
    let mut with_hard = 0;
    let mut nonzero = 0;
    for seed in 0..150 {
        let spec = random_spec(seed);
        if spec
            .tlinks
            .iter()
            .any(|&(_, s, t)| s.is_infinite() || t.is_infinite())
        {
            with_hard += 1;
        }
        let (flow, _) = check(&spec, &format!("random graph seed {seed}"));
        if flow > 0.0 {
            nonzero += 1;
        }
    }
    // The generator must actually exercise hard links and non-trivial flows.
    assert!(with_hard >= 30, "only {with_hard} graphs with hard t-links");
    assert!(nonzero >= 100, "only {nonzero} graphs with positive flow");
}

#[test]
fn two_node_graph() {
    let spec = Spec {
        nodes: 2,
        edges: vec![(0, 1, 3.0, 1.0)],
        tlinks: vec![(0, 5.0, 0.0), (1, 0.0, 4.0)],
    };
    let (flow, seg) = check(&spec, "two nodes");
    assert_eq!(flow, 3.0);
    assert_eq!(seg, [true, false]);

    // Reversed orientation: only the 1-capacity direction can carry flow.
    let spec = Spec {
        nodes: 2,
        edges: vec![(0, 1, 3.0, 1.0)],
        tlinks: vec![(1, 5.0, 0.0), (0, 0.0, 4.0)],
    };
    let (flow, seg) = check(&spec, "two nodes reversed");
    assert_eq!(flow, 1.0);
    assert_eq!(seg, [false, true]);
}

#[test]
fn node_linked_to_both_terminals() {
    let spec = Spec {
        nodes: 1,
        edges: vec![],
        tlinks: vec![(0, 2.5, 7.0), (0, 1.0, 0.0)],
    };
    let (flow, seg) = check(&spec, "one node, both terminals");
    assert_eq!(flow, 3.5);
    assert_eq!(seg, [false]);
}

#[test]
fn chain_cuts_at_its_weakest_edge() {
    let caps = [9.0, 7.0, 8.0, 2.5, 6.0, 9.0, 3.0, 8.0];
    let spec = Spec {
        nodes: caps.len() + 1,
        edges: caps
            .iter()
            .enumerate()
            .map(|(i, &c)| (i as u32, i as u32 + 1, c, c))
            .collect(),
        tlinks: vec![(0, f64::INFINITY, 0.0), (caps.len() as u32, 0.0, 100.0)],
    };
    let (flow, seg) = check(&spec, "chain");
    assert_eq!(flow, 2.5);
    let expected: Vec<bool> = (0..=caps.len()).map(|i| i <= 3).collect();
    assert_eq!(seg, expected);
}

/// A `w × h` 4-connected grid, node `y * w + x`, with `cap(x, y, horizontal)`
/// on each undirected edge, the left column tied to the source and the right
/// column tied to the sink by hard t-links.
fn grid_spec(w: u32, h: u32, mut cap: impl FnMut(u32, u32, bool) -> f64) -> Spec {
    let mut spec = Spec {
        nodes: (w * h) as usize,
        ..Spec::default()
    };
    for y in 0..h {
        for x in 0..w {
            let v = y * w + x;
            if x + 1 < w {
                let c = cap(x, y, true);
                spec.edges.push((v, v + 1, c, c));
            }
            if y + 1 < h {
                let c = cap(x, y, false);
                spec.edges.push((v, v + w, c, c));
            }
        }
        spec.tlinks.push((y * w, f64::INFINITY, 0.0));
        spec.tlinks.push((y * w + w - 1, 0.0, f64::INFINITY));
    }
    spec
}

#[test]
fn grid_with_a_known_bottleneck() {
    // Horizontal edges between columns 9 and 10 are weak: the cut runs there.
    let (w, h) = (20, 15);
    let spec = grid_spec(
        w,
        h,
        |x, _, horizontal| {
            if horizontal && x == 9 { 1.0 } else { 10.0 }
        },
    );
    let (flow, seg) = check(&spec, "grid bottleneck");
    assert_eq!(flow, f64::from(h));
    for (v, &s) in seg.iter().enumerate() {
        assert_eq!(s, (v as u32 % w) <= 9, "node {v} on the wrong side");
    }
}

#[test]
fn grid_100x100() {
    // Uniform capacities: any column of horizontal edges is a minimum cut.
    let spec = grid_spec(100, 100, |_, _, _| 2.0);
    let (flow, _) = check(&spec, "uniform 100x100 grid");
    assert_eq!(flow, 200.0);

    // Texture-seam-like weights: colour mismatch of two random images.
    let mut rng = Pcg64::seed_from_u64(7);
    let (w, h) = (100u32, 100u32);
    let mismatch: Vec<f64> = (0..w * h).map(|_| rng.random_range(0.0..1.0)).collect();
    let spec = grid_spec(w, h, |x, y, horizontal| {
        let v = (y * w + x) as usize;
        let u = if horizontal { v + 1 } else { v + w as usize };
        mismatch[v] + mismatch[u] + 1e-3
    });
    check(&spec, "random 100x100 grid");
}

#[test]
fn conflicting_hard_links_give_infinite_flow() {
    let mut g = FlowGraph::new(3);
    g.add_terminal_weights(0, f64::from(f32::INFINITY), 0.0);
    g.add_terminal_weights(2, 0.0, f64::INFINITY);
    g.add_edge(0, 1, f64::INFINITY, f64::INFINITY);
    g.add_edge(1, 2, f64::INFINITY, 0.0);
    assert_eq!(g.max_flow(), f64::INFINITY);
    assert_eq!(g.cut_value(), f64::INFINITY);

    // One node on both terminals with infinite weight.
    let mut g = FlowGraph::new(1);
    g.add_terminal_weights(0, f64::INFINITY, f64::INFINITY);
    assert_eq!(g.max_flow(), f64::INFINITY);
}

#[test]
fn solving_again_after_more_edges() {
    let mut g = FlowGraph::new(3);
    g.add_terminal_weights(0, 10.0, 0.0);
    g.add_terminal_weights(2, 0.0, 10.0);
    g.add_edge(0, 1, 4.0, 4.0);
    g.add_edge(1, 2, 3.0, 3.0);
    assert_eq!(g.max_flow(), 3.0);
    assert_eq!(g.max_flow(), 3.0, "a second call solves the same graph");
    g.add_edge(0, 2, 5.0, 0.0);
    assert_eq!(g.max_flow(), 8.0);
    assert_eq!(g.cut_value(), 8.0);
}

#[test]
fn self_loops_and_zero_edges_are_harmless() {
    let spec = Spec {
        nodes: 3,
        edges: vec![(0, 0, 5.0, 5.0), (0, 1, 0.0, 0.0), (1, 2, 2.0, 0.0)],
        tlinks: vec![(0, 1.0, 0.0), (1, 3.0, 0.0), (2, 0.0, 9.0)],
    };
    let (flow, seg) = check(&spec, "self-loop");
    assert_eq!(flow, 2.0);
    assert_eq!(seg, [true, true, false]);
}

#[test]
#[should_panic(expected = "call max_flow")]
fn segment_before_solving_panics() {
    let g = FlowGraph::new(2);
    g.in_source_segment(0);
}

#[test]
#[should_panic(expected = "must be >= 0")]
fn negative_capacity_panics() {
    let mut g = FlowGraph::new(2);
    g.add_edge(0, 1, -1.0, 0.0);
}

#[test]
#[should_panic(expected = "must be >= 0")]
fn nan_capacity_panics() {
    let mut g = FlowGraph::new(2);
    g.add_terminal_weights(1, f64::NAN, 0.0);
}

/// The seam weights of `benches/max_flow.rs`: per-pixel mismatch of a smooth
/// low-frequency term plus the noise of random RGB differences, an n-link
/// weighing the mismatch at both ends; left column tied to the source and
/// right column to the sink.
fn bench_seam_spec(w: u32, h: u32, seed: u64) -> Spec {
    let mut rng = Pcg64::seed_from_u64(seed);
    let mismatch: Vec<f64> = (0..w * h)
        .map(|p| {
            let (x, y) = (f64::from(p % w), f64::from(p / w));
            let smooth = 0.5 + 0.5 * (x * 0.05).sin() * (y * 0.07).cos();
            let noise: f64 = (0..3)
                .map(|_| (rng.random::<f64>() - rng.random::<f64>()).abs())
                .sum();
            smooth + noise
        })
        .collect();
    grid_spec(w, h, |x, y, horizontal| {
        let v = (y * w + x) as usize;
        let u = if horizontal { v + 1 } else { v + w as usize };
        mismatch[v] + mismatch[u]
    })
}

/// The segmentation grid of `benches/max_flow.rs`: t-links on every node
/// (data term of a noisy two-level image), contrast-weighted n-links.
fn bench_segmentation_spec(w: u32, h: u32, seed: u64) -> Spec {
    let mut rng = Pcg64::seed_from_u64(seed);
    let image: Vec<f64> = (0..w * h)
        .map(|p| {
            let (x, y) = (f64::from(p % w), f64::from(p / w));
            let blob = (0.5 + 0.5 * (x * 0.11).sin() * (y * 0.13).cos() > 0.5) as u8;
            (0.3 + 0.4 * f64::from(blob) + rng.random_range(-0.25..0.25)).clamp(0.0, 1.0)
        })
        .collect();
    let mut spec = Spec {
        nodes: (w * h) as usize,
        ..Spec::default()
    };
    for y in 0..h {
        for x in 0..w {
            let v = y * w + x;
            let i = image[v as usize];
            spec.tlinks
                .push((v, 10.0 * (i - 0.3).powi(2), 10.0 * (i - 0.7).powi(2)));
            let mut link = |u: u32| {
                let d = i - image[u as usize];
                let c = 2.0 * (-d * d / 0.02).exp();
                spec.edges.push((v, u, c, c));
            };
            if x + 1 < w {
                link(v + 1);
            }
            if y + 1 < h {
                link(v + w);
            }
        }
    }
    spec
}

#[test]
fn grids_with_the_bench_weights_match_dinics() {
    // The bench's square and band seam shapes, scaled down so Dinic is quick.
    for (w, h, seed) in [(60u32, 60u32, 42u64), (32, 200, 43), (25, 25, 44)] {
        let spec = bench_seam_spec(w, h, seed);
        let (flow, seg) = check(&spec, &format!("seam grid {w}x{h}"));
        assert!(flow > 0.0 && flow.is_finite());
        // The cut separates the tied columns: left is source, right sink.
        assert!((0..h).all(|y| seg[(y * w) as usize] && !seg[(y * w + w - 1) as usize]));
    }
    for (w, h, seed) in [(80u32, 80u32, 5u64), (50, 30, 6)] {
        let spec = bench_segmentation_spec(w, h, seed);
        let (flow, seg) = check(&spec, &format!("segmentation grid {w}x{h}"));
        // Both labels occur: the blobs are segmented out.
        let fg = seg.iter().filter(|&&s| s).count();
        assert!(
            fg > 0 && fg < seg.len(),
            "{fg} of {} in the source segment",
            seg.len()
        );
        assert!(flow > 0.0);
    }
}
