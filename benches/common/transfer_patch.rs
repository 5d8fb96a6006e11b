//! The texture-transfer graph of Bangay & Morkel §3.4, shared by the
//! max-flow and roofline benches (included with `#[path]`).

use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use surfsynth::kernels::bangay_morkel::max_flow::FlowGraph;

/// The texture-transfer graph of Bangay & Morkel §3.4 on a `side × side`
/// neighbourhood (`side` odd), seeded.
pub fn transfer_patch(side: u32, seed: u64) -> FlowGraph {
    let mut rng = Pcg64::seed_from_u64(seed);
    let n = (side * side) as usize;
    let mismatch: Vec<f64> = (0..n).map(|_| rng.random_range(0.0..3.0)).collect();
    let c = f64::from(side / 2);
    let r2 = f64::from(side) * f64::from(side);
    let x2 = |v: u32| {
        let (x, y) = (f64::from(v % side) - c, f64::from(v / side) - c);
        x * x + y * y
    };
    let weight = |a: u32, b: u32| {
        (mismatch[a as usize] + mismatch[b as usize]) * (-(x2(a) + x2(b)) / r2).exp()
    };
    let mut g = FlowGraph::with_capacity(n, 2 * n);
    for y in 0..side {
        for x in 0..side {
            let v = y * side + x;
            if x + 1 < side {
                let w = weight(v, v + 1);
                g.add_edge(v, v + 1, w, w);
            }
            if y + 1 < side {
                let w = weight(v, v + side);
                g.add_edge(v, v + side, w, w);
            }
            if x == 0 || y == 0 || x + 1 == side || y + 1 == side {
                g.add_terminal_weights(v, 0.0, f64::INFINITY);
            }
        }
    }
    g.add_terminal_weights(n as u32 / 2, f64::INFINITY, 0.0);
    g
}
