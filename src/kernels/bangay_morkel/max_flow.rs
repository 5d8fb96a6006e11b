//! Minimum s-t cut by the Boykov–Kolmogorov max-flow algorithm
//! (`max_flow_bk`).
//!
//! Y. Boykov and V. Kolmogorov, "An experimental comparison of
//! min-cut/max-flow algorithms for energy minimization in vision", IEEE TPAMI
//! 26(9):1124–1137, 2004, §3 (growth, augmentation and adoption stages), with
//! the refinements of Kolmogorov's reference implementation (maxflow v3):
//! t-links stored as one signed residual per node after subtracting the
//! common part of the source and sink capacities, the "origin check" with
//! timestamps and distances in the adoption stage, the distance heuristic
//! while growing, and a FIFO queue of active nodes.
//!
//! Bangay & Morkel 2006 §3.4 (after Kwatra et al. 2003) transfer texture with
//! exactly this solver: one node per vertex of the matched region, n-links
//! weighted by the colour mismatch, the target vertex tied to the texture
//! terminal and the coloured border tied to the surface terminal, both with
//! infinite weight.
//!
//! Layout: the graph is kept as given (edge list and per-node terminal
//! capacities). [`FlowGraph::max_flow`] builds a CSR residual graph from it
//! (arcs grouped by tail; each arc holds its head, its reverse arc and its
//! residual capacity in 16 bytes) and a 16-byte search-tree record per node
//! holding the parent arc *and* the parent node, so walks up a tree touch
//! node records only. Tree arcs are stored oriented along the flow (parent →
//! child in S, child → parent in T), which makes both halves of an
//! augmenting path read the same field. No allocation happens per node and
//! nothing recurses.
//!
//! Performance: near-linear when augmenting paths are short (t-links on many
//! nodes, narrow seams). When the only t-links are far apart, e.g. a square
//! grid tied to the terminals along two opposite sides, paths are hundreds
//! of arcs long, most orphaned subtrees find no new parent and are regrown,
//! and the time grows superlinearly with the size (an inherent weakness of
//! BK on such graphs, see `benches/max_flow.rs` for figures).

use std::collections::VecDeque;

/// Capacities at or above this value, including `f64::INFINITY`, are hard
/// constraints: they are clamped to this finite value so the residual
/// arithmetic never produces NaN (∞ − ∞). A flow or cut of at least this
/// value is reported as `f64::INFINITY` (the hard constraints conflict: some
/// path from the source to the sink consists only of hard edges).
///
/// Precondition for exact results: the sum of all finite capacities is far
/// below this value (so that `HARD_CAPACITY − finite flow` rounds back to
/// `HARD_CAPACITY` and a hard edge is never saturated by finite flow).
pub const HARD_CAPACITY: f64 = 1e100;

/// Parent sentinel: the node belongs to no search tree.
const NONE: u32 = u32::MAX;
/// Parent sentinel: the node is a root, linked directly to its terminal.
const TERMINAL: u32 = u32::MAX - 1;
/// Parent sentinel: the node lost its parent arc and awaits adoption.
const ORPHAN: u32 = u32::MAX - 2;
/// Distance standing for "not connected to the terminal" in the origin check.
const INFINITE_DIST: u32 = u32::MAX;
/// Node ids and arc indices must stay below the sentinels.
const MAX_INDEX: usize = (u32::MAX - 3) as usize;

/// One directed residual arc, stored in CSR order (grouped by tail).
#[derive(Clone, Copy, Debug)]
struct ResidualArc {
    /// Node the arc points to.
    head: u32,
    /// Index of the reverse arc `head → tail`.
    sister: u32,
    /// Residual capacity (≥ 0).
    r_cap: f64,
}

/// `NodeState::meta` bit: the node belongs to the sink tree T (meaningful
/// only while it has a parent).
const SINK_BIT: u32 = 1 << 31;
/// `NodeState::meta` bit: the node is in the active queue (or is the node
/// being grown).
const QUEUED_BIT: u32 = 1 << 30;
/// `NodeState::meta` bits holding the distance to the terminal. Distances
/// only guide heuristics, so they saturate.
const DIST_MASK: u32 = QUEUED_BIT - 1;

/// Search-tree state of one node: 16 bytes, so four nodes share a cache
/// line. The signed t-link residual lives apart (`FlowGraph::tr_cap`): it is
/// read only at tree roots.
#[derive(Clone, Copy, Debug)]
struct NodeState {
    /// The tree arc joining this node to its parent, or `NONE` (free),
    /// `TERMINAL` (root) or `ORPHAN`. The arc is oriented along the flow:
    /// parent → node in the source tree S, node → parent in the sink tree T,
    /// so in both trees its residual capacity is the one that must stay
    /// positive.
    parent: u32,
    /// The parent node (valid only when `parent` is an arc), so walks up a
    /// tree touch node records only.
    parent_node: u32,
    /// Timestamp of the last time `dist` was known to be exact.
    ts: u32,
    /// `SINK_BIT | QUEUED_BIT | distance` (roots have distance 1).
    meta: u32,
}

impl NodeState {
    #[inline]
    fn is_sink(self) -> bool {
        self.meta & SINK_BIT != 0
    }

    #[inline]
    fn queued(self) -> bool {
        self.meta & QUEUED_BIT != 0
    }

    #[inline]
    fn dist(self) -> u32 {
        self.meta & DIST_MASK
    }

    /// Joins tree `sink_bit` (0 or `SINK_BIT`) at distance `dist`, keeping
    /// the queue flag.
    #[inline]
    fn set_tree(&mut self, sink_bit: u32, dist: u32) {
        self.meta = (self.meta & QUEUED_BIT) | sink_bit | dist.min(DIST_MASK);
    }

    #[inline]
    fn set_dist(&mut self, dist: u32) {
        self.meta = (self.meta & !DIST_MASK) | dist.min(DIST_MASK);
    }

    #[inline]
    fn set_queued(&mut self, queued: bool) {
        if queued {
            self.meta |= QUEUED_BIT;
        } else {
            self.meta &= !QUEUED_BIT;
        }
    }
}

const FREE_NODE: NodeState = NodeState {
    parent: NONE,
    parent_node: NONE,
    ts: 0,
    meta: 0,
};

/// A flow network over nodes `0..nodes` plus two implicit terminals, the
/// source and the sink; solved by Boykov–Kolmogorov.
///
/// Capacities are `f64`: the texture-transfer graphs of Bangay & Morkel
/// §3.4 sum many colour differences, and with `f32` residuals the rounding
/// of many thousands of augmentations would make the flow and the cut value
/// drift apart (callers with `f32` weights convert with `f64::from`). Units are whatever
/// the caller's weights are (e.g. colour distance).
///
/// Typical use: `new`, then `add_edge` / `add_terminal_weights`, then
/// `max_flow`, then `in_source_segment` per node.
#[derive(Clone, Debug)]
pub struct FlowGraph {
    // The graph as given (capacities clamped to HARD_CAPACITY), kept so that
    // `max_flow` can be rerun after more edges are added and `cut_value` can
    // be evaluated independently of the residual state.
    edge_ends: Vec<[u32; 2]>,
    edge_caps: Vec<[f64; 2]>,
    source_caps: Vec<f64>,
    sink_caps: Vec<f64>,
    // Solver state, rebuilt by every `max_flow` call.
    first: Vec<u32>,
    arcs: Vec<ResidualArc>,
    nodes: Vec<NodeState>,
    tr_cap: Vec<f64>,
    active: VecDeque<u32>,
    orphans: VecDeque<u32>,
    cascade: VecDeque<u32>,
    time: u32,
    flow: f64,
    solved: bool,
}

fn check_capacity(cap: f64, what: &str, a: u32, b: u32) -> f64 {
    assert!(
        cap >= 0.0,
        "FlowGraph: capacity of {what} ({a}, {b}) is {cap}; capacities must be >= 0 and not NaN"
    );
    cap.min(HARD_CAPACITY)
}

impl FlowGraph {
    /// A graph with `nodes` nodes (ids `0..nodes`), no edges and no t-links.
    ///
    /// # Panics
    /// If `nodes` exceeds `u32::MAX - 3` (ids are `u32`, the top values are
    /// reserved).
    pub fn new(nodes: usize) -> Self {
        Self::with_capacity(nodes, 0)
    }

    /// Like [`FlowGraph::new`], reserving room for `edges` calls of
    /// [`FlowGraph::add_edge`].
    pub fn with_capacity(nodes: usize, edges: usize) -> Self {
        assert!(
            nodes <= MAX_INDEX,
            "FlowGraph: {nodes} nodes, at most {MAX_INDEX} are supported"
        );
        Self {
            edge_ends: Vec::with_capacity(edges),
            edge_caps: Vec::with_capacity(edges),
            source_caps: vec![0.0; nodes],
            sink_caps: vec![0.0; nodes],
            first: Vec::new(),
            arcs: Vec::new(),
            nodes: Vec::new(),
            tr_cap: Vec::new(),
            active: VecDeque::new(),
            orphans: VecDeque::new(),
            cascade: VecDeque::new(),
            time: 0,
            flow: 0.0,
            solved: false,
        }
    }

    /// Number of non-terminal nodes.
    pub fn num_nodes(&self) -> usize {
        self.source_caps.len()
    }

    /// Adds the edge pair `a → b` with capacity `cap_ab` and `b → a` with
    /// `cap_ba` (an undirected n-link has `cap_ab == cap_ba`). Parallel edges
    /// add up. A self-loop (`a == b`) never crosses a cut and is ignored.
    /// Capacities ≥ [`HARD_CAPACITY`] (e.g. `f64::INFINITY`) are hard.
    ///
    /// # Panics
    /// If `a` or `b` is not a node id, or a capacity is negative or NaN.
    pub fn add_edge(&mut self, a: u32, b: u32, cap_ab: f64, cap_ba: f64) {
        let n = self.num_nodes();
        assert!(
            (a as usize) < n && (b as usize) < n,
            "FlowGraph::add_edge({a}, {b}): node ids must be < {n}"
        );
        let cap_ab = check_capacity(cap_ab, "edge", a, b);
        let cap_ba = check_capacity(cap_ba, "edge", b, a);
        if a == b {
            return;
        }
        assert!(
            2 * (self.edge_ends.len() + 1) <= MAX_INDEX,
            "FlowGraph::add_edge: too many edges for u32 arc indices"
        );
        self.edge_ends.push([a, b]);
        self.edge_caps.push([cap_ab, cap_ba]);
        self.solved = false;
    }

    /// Adds t-links: capacity `source_cap` from the source to `node` and
    /// `sink_cap` from `node` to the sink. Repeated calls add up. A node may
    /// be linked to both terminals; the common part `min(source, sink)` is
    /// flow that saturates both links whatever the cut, and is subtracted up
    /// front as in the reference implementation. Capacities ≥
    /// [`HARD_CAPACITY`] (e.g. `f64::INFINITY`) tie the node to that terminal.
    ///
    /// # Panics
    /// If `node` is not a node id, or a capacity is negative or NaN.
    pub fn add_terminal_weights(&mut self, node: u32, source_cap: f64, sink_cap: f64) {
        let n = self.num_nodes();
        assert!(
            (node as usize) < n,
            "FlowGraph::add_terminal_weights({node}): node ids must be < {n}"
        );
        let s = check_capacity(source_cap, "t-link", node, node);
        let t = check_capacity(sink_cap, "t-link", node, node);
        let i = node as usize;
        self.source_caps[i] = (self.source_caps[i] + s).min(HARD_CAPACITY);
        self.sink_caps[i] = (self.sink_caps[i] + t).min(HARD_CAPACITY);
        self.solved = false;
    }

    /// Computes the maximum flow from the source to the sink (Boykov &
    /// Kolmogorov 2004 §3) and with it the minimum cut queried by
    /// [`FlowGraph::in_source_segment`]. Returns the flow value, in the units
    /// of the capacities, or `f64::INFINITY` when hard constraints conflict.
    ///
    /// Each call solves from scratch over all edges added so far, in
    /// O(E) memory; the running time is not polynomially bounded in theory
    /// but is near-linear on graphs with short augmenting paths.
    #[doc(alias = "max_flow_bk")]
    pub fn max_flow(&mut self) -> f64 {
        self.build_residual_graph();
        self.init_trees();
        let mut current = NONE;
        loop {
            // Keep growing the node that found the last path, as long as it
            // is still in a tree; otherwise take the next active node.
            let mut i = NONE;
            if current != NONE {
                let c = &mut self.nodes[current as usize];
                c.set_queued(false);
                if c.parent != NONE {
                    i = current;
                }
            }
            if i == NONE {
                match self.next_active() {
                    Some(n) => i = n,
                    None => break,
                }
            }
            let path = self.grow(i);
            self.tick();
            match path {
                None => current = NONE,
                Some(middle) => {
                    // The queue flag marks `i` as active without queueing
                    // it: it is grown again on the next iteration.
                    self.nodes[i as usize].set_queued(true);
                    current = i;
                    self.augment(middle);
                    self.adopt_orphans();
                }
            }
        }
        self.solved = true;
        if self.flow >= HARD_CAPACITY {
            f64::INFINITY
        } else {
            self.flow
        }
    }

    /// Whether `node` is on the source side of the minimum cut: reachable
    /// from the source in the residual graph after [`FlowGraph::max_flow`].
    /// Nodes tied to the source by a hard t-link are always in it and nodes
    /// tied to the sink never are (unless the constraints conflict).
    ///
    /// # Panics
    /// If `max_flow` has not been called since the graph last changed, or
    /// `node` is not a node id.
    pub fn in_source_segment(&self, node: u32) -> bool {
        assert!(
            self.solved,
            "FlowGraph::in_source_segment: call max_flow after the last change"
        );
        let s = self.nodes[node as usize];
        s.parent != NONE && !s.is_sink()
    }

    /// The capacity of the cut given by [`FlowGraph::in_source_segment`],
    /// summed from the capacities as given (not from the residual graph):
    /// t-links from the source to sink-side nodes, t-links from source-side
    /// nodes to the sink, and edges from the source side to the sink side.
    /// Equals the max-flow value up to rounding (max-flow/min-cut theorem);
    /// `f64::INFINITY` when the cut contains a hard edge.
    ///
    /// # Panics
    /// If `max_flow` has not been called since the graph last changed.
    pub fn cut_value(&self) -> f64 {
        assert!(
            self.solved,
            "FlowGraph::cut_value: call max_flow after the last change"
        );
        let mut cut = 0.0;
        for v in 0..self.num_nodes() {
            cut += if self.in_source_segment(v as u32) {
                self.sink_caps[v]
            } else {
                self.source_caps[v]
            };
        }
        for (&[a, b], &[cab, cba]) in self.edge_ends.iter().zip(&self.edge_caps) {
            match (self.in_source_segment(a), self.in_source_segment(b)) {
                (true, false) => cut += cab,
                (false, true) => cut += cba,
                _ => {}
            }
        }
        if cut >= HARD_CAPACITY {
            f64::INFINITY
        } else {
            cut
        }
    }

    /// Builds the CSR residual graph from the edge list (counting sort by
    /// tail); edge pairs with both capacities zero are left out.
    fn build_residual_graph(&mut self) {
        let n = self.num_nodes();
        self.first.clear();
        self.first.resize(n + 1, 0);
        for (&[a, b], &[cab, cba]) in self.edge_ends.iter().zip(&self.edge_caps) {
            if cab > 0.0 || cba > 0.0 {
                self.first[a as usize + 1] += 1;
                self.first[b as usize + 1] += 1;
            }
        }
        for v in 0..n {
            self.first[v + 1] += self.first[v];
        }
        let m = self.first[n] as usize;
        self.arcs.clear();
        self.arcs.resize(
            m,
            ResidualArc {
                head: 0,
                sister: 0,
                r_cap: 0.0,
            },
        );
        // `fill[v]` is the next free arc slot of node v.
        let mut fill: Vec<u32> = self.first[..n].to_vec();
        for (&[a, b], &[cab, cba]) in self.edge_ends.iter().zip(&self.edge_caps) {
            if cab > 0.0 || cba > 0.0 {
                let pa = fill[a as usize];
                let pb = fill[b as usize];
                fill[a as usize] += 1;
                fill[b as usize] += 1;
                self.arcs[pa as usize] = ResidualArc {
                    head: b,
                    sister: pb,
                    r_cap: cab,
                };
                self.arcs[pb as usize] = ResidualArc {
                    head: a,
                    sister: pa,
                    r_cap: cba,
                };
            }
        }
    }

    /// Subtracts the common part of each node's t-links (that flow is
    /// counted at once) and makes every node with a residual t-link an
    /// active root of its terminal's tree.
    fn init_trees(&mut self) {
        let n = self.num_nodes();
        self.nodes.clear();
        self.nodes.resize(n, FREE_NODE);
        self.tr_cap.clear();
        self.tr_cap.resize(n, 0.0);
        self.active.clear();
        self.active.reserve(n);
        self.orphans.clear();
        self.cascade.clear();
        self.time = 0;
        self.flow = 0.0;
        for v in 0..n {
            let (s, t) = (self.source_caps[v], self.sink_caps[v]);
            self.flow += s.min(t);
            let tr = s - t;
            self.tr_cap[v] = tr;
            if tr != 0.0 {
                let node = &mut self.nodes[v];
                node.parent = TERMINAL;
                node.set_tree(if tr < 0.0 { SINK_BIT } else { 0 }, 1);
                node.set_queued(true);
                self.active.push_back(v as u32);
            }
        }
    }

    /// Queues `v` as active unless it already is.
    #[inline]
    fn set_active(&mut self, v: u32) {
        let node = &mut self.nodes[v as usize];
        if !node.queued() {
            node.set_queued(true);
            self.active.push_back(v);
        }
    }

    /// Pops active nodes until one still in a tree is found.
    fn next_active(&mut self) -> Option<u32> {
        while let Some(v) = self.active.pop_front() {
            let node = &mut self.nodes[v as usize];
            node.set_queued(false);
            if node.parent != NONE {
                return Some(v);
            }
        }
        None
    }

    /// Advances the timestamp; on wrap-around all marks are invalidated.
    fn tick(&mut self) {
        if self.time == u32::MAX - 1 {
            for node in &mut self.nodes {
                node.ts = 0;
            }
            self.time = 1;
        } else {
            self.time += 1;
        }
    }

    /// Growth stage (§3.1): the active node `i` claims free neighbours
    /// through non-saturated arcs. Returns the path found when its tree
    /// touches the other one: the joining arc, directed from the source tree
    /// to the sink tree, with its tail and head.
    #[inline]
    fn grow(&mut self, i: u32) -> Option<[u32; 3]> {
        let lo = self.first[i as usize] as usize;
        let hi = self.first[i as usize + 1] as usize;
        let ni = self.nodes[i as usize];
        let sink_bit = ni.meta & SINK_BIT;
        let child_dist = ni.dist() + 1;
        for a in lo..hi {
            let arc = self.arcs[a];
            // The arc along the flow: i → j in S, j → i in T.
            let flow_arc = if sink_bit != 0 { arc.sister } else { a as u32 };
            if self.arcs[flow_arc as usize].r_cap <= 0.0 {
                continue;
            }
            let j = arc.head;
            let nj = &mut self.nodes[j as usize];
            if nj.parent == NONE {
                nj.parent = flow_arc;
                nj.parent_node = i;
                nj.ts = ni.ts;
                nj.set_tree(sink_bit, child_dist);
                self.set_active(j);
            } else if nj.meta & SINK_BIT != sink_bit {
                return Some(if sink_bit != 0 {
                    [flow_arc, j, i]
                } else {
                    [flow_arc, i, j]
                });
            } else if nj.ts <= ni.ts && nj.dist() > ni.dist() {
                // Heuristic of the reference implementation: shorten the
                // path from j to its terminal.
                nj.parent = flow_arc;
                nj.parent_node = i;
                nj.ts = ni.ts;
                nj.set_dist(child_dist);
            }
        }
        None
    }

    /// Augmentation stage (§3.2): pushes the bottleneck capacity along the
    /// path source → … → tail → head → … → sink given by `[middle, tail,
    /// head]`; nodes whose tree arc or t-link saturates become orphans.
    fn augment(&mut self, [middle, tail, head]: [u32; 3]) {
        let arcs = &mut self.arcs;
        let nodes = &mut self.nodes;

        // Bottleneck over the middle arc and both tree paths: every tree arc
        // is oriented along the flow, so both halves read the same field.
        let mut bottleneck = arcs[middle as usize].r_cap;
        let mut roots = [tail, head];
        for root in &mut roots {
            let mut i = *root;
            loop {
                let node = nodes[i as usize];
                if node.parent == TERMINAL {
                    break;
                }
                bottleneck = bottleneck.min(arcs[node.parent as usize].r_cap);
                i = node.parent_node;
            }
            *root = i;
        }
        let [s_root, t_root] = roots;
        bottleneck = bottleneck
            .min(self.tr_cap[s_root as usize])
            .min(-self.tr_cap[t_root as usize]);

        // Push it. `x - bottleneck` is exactly 0 where x is the bottleneck
        // and never negative elsewhere, so saturation tests are exact.
        let m = &mut arcs[middle as usize];
        m.r_cap -= bottleneck;
        let sister = m.sister;
        arcs[sister as usize].r_cap += bottleneck;
        for start in [tail, head] {
            let mut i = start;
            loop {
                let node = nodes[i as usize];
                if node.parent == TERMINAL {
                    break;
                }
                let arc = &mut arcs[node.parent as usize];
                arc.r_cap -= bottleneck;
                let (saturated, sister) = (arc.r_cap == 0.0, arc.sister);
                arcs[sister as usize].r_cap += bottleneck;
                if saturated {
                    nodes[i as usize].parent = ORPHAN;
                    self.orphans.push_front(i);
                }
                i = node.parent_node;
            }
        }
        self.tr_cap[s_root as usize] -= bottleneck;
        self.tr_cap[t_root as usize] += bottleneck;
        for root in [s_root, t_root] {
            if self.tr_cap[root as usize] == 0.0 {
                nodes[root as usize].parent = ORPHAN;
                self.orphans.push_front(root);
            }
        }
        self.flow += bottleneck;
    }

    /// Adoption stage (§3.3). As in the reference implementation each
    /// orphan from the augmentation is processed together with all orphans
    /// it creates before the next one.
    fn adopt_orphans(&mut self) {
        while let Some(o) = self.orphans.pop_front() {
            self.process_orphan(o);
            while let Some(c) = self.cascade.pop_front() {
                self.process_orphan(c);
            }
        }
    }

    /// Finds orphan `i` a new parent in its own tree whose path reaches the
    /// terminal (the origin check), preferring the shortest such path; if
    /// none exists, `i` becomes free, its children become orphans and its
    /// tree neighbours that could regrow into it become active.
    fn process_orphan(&mut self, i: u32) {
        let time = self.time;
        let sink_bit = self.nodes[i as usize].meta & SINK_BIT;
        let lo = self.first[i as usize] as usize;
        let hi = self.first[i as usize + 1] as usize;
        let mut best = NONE;
        let mut best_node = NONE;
        let mut best_dist = INFINITE_DIST;
        for a0 in lo..hi {
            let arc0 = self.arcs[a0];
            // The arc along the flow between i and the candidate parent j:
            // j → i in S, i → j in T.
            let flow_arc = if sink_bit != 0 {
                a0 as u32
            } else {
                arc0.sister
            };
            if self.arcs[flow_arc as usize].r_cap <= 0.0 {
                continue;
            }
            let j0 = arc0.head;
            let nj = self.nodes[j0 as usize];
            if nj.meta & SINK_BIT != sink_bit || nj.parent == NONE {
                continue;
            }
            // Origin check: walk up until a terminal, an orphan or a node
            // already verified in this round.
            let mut d = 0u32;
            let mut j = j0;
            loop {
                let node = &mut self.nodes[j as usize];
                if node.ts == time {
                    d = d.saturating_add(node.dist());
                    break;
                }
                d += 1;
                if node.parent == TERMINAL {
                    node.ts = time;
                    node.set_dist(1);
                    break;
                }
                if node.parent == ORPHAN {
                    d = INFINITE_DIST;
                    break;
                }
                j = node.parent_node;
            }
            if d == INFINITE_DIST {
                continue;
            }
            if d < best_dist {
                best = flow_arc;
                best_node = j0;
                best_dist = d;
            }
            // Mark the verified path with exact distances.
            let mut j = j0;
            loop {
                let node = &mut self.nodes[j as usize];
                if node.ts == time {
                    break;
                }
                node.ts = time;
                node.set_dist(d);
                d = d.saturating_sub(1);
                j = node.parent_node;
            }
        }

        if best != NONE {
            let node = &mut self.nodes[i as usize];
            node.parent = best;
            node.parent_node = best_node;
            node.ts = time;
            node.set_dist(best_dist.saturating_add(1));
            return;
        }

        self.nodes[i as usize].parent = NONE;
        for a0 in lo..hi {
            let arc0 = self.arcs[a0];
            let j = arc0.head;
            let nj = self.nodes[j as usize];
            if nj.meta & SINK_BIT != sink_bit || nj.parent == NONE {
                continue;
            }
            // j could regrow into i along the flow: j → i in S, i → j in T.
            let regrow_arc = if sink_bit != 0 {
                a0 as u32
            } else {
                arc0.sister
            };
            if self.arcs[regrow_arc as usize].r_cap > 0.0 {
                self.set_active(j);
            }
            if nj.parent != TERMINAL && nj.parent != ORPHAN && nj.parent_node == i {
                self.nodes[j as usize].parent = ORPHAN;
                self.cascade.push_back(j);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_nodes() {
        let mut g = FlowGraph::new(2);
        g.add_terminal_weights(0, 5.0, 0.0);
        g.add_terminal_weights(1, 0.0, 4.0);
        g.add_edge(0, 1, 3.0, 1.0);
        assert_eq!(g.max_flow(), 3.0);
        assert!(g.in_source_segment(0));
        assert!(!g.in_source_segment(1));
        assert_eq!(g.cut_value(), 3.0);
    }

    #[test]
    fn both_terminals_on_one_node() {
        let mut g = FlowGraph::new(1);
        g.add_terminal_weights(0, 2.0, 7.0);
        assert_eq!(g.max_flow(), 2.0);
        assert!(!g.in_source_segment(0));
        assert_eq!(g.cut_value(), 2.0);
    }

    #[test]
    fn conflicting_hard_constraints_are_infinite() {
        let mut g = FlowGraph::new(2);
        g.add_terminal_weights(0, f64::INFINITY, 0.0);
        g.add_terminal_weights(1, 0.0, f64::INFINITY);
        g.add_edge(0, 1, f64::INFINITY, 0.0);
        assert_eq!(g.max_flow(), f64::INFINITY);
        assert_eq!(g.cut_value(), f64::INFINITY);
    }
}
