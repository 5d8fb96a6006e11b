//! How often a synthesis uses each cell of the exemplar: the occurrence
//! penalty of the coherent syntheses (an extension, after the occurrence
//! maps of Kaspar et al. 2015). A candidate in an over-used cell costs
//! more, so a result spreads over all of the exemplar's content instead of
//! settling on its easiest-to-match parts. `kernels::coherent` and
//! `kernels::bangay_morkel::graph_match` (coherent candidates) read it, each with its own
//! share and penalty.

use glam::Vec2;

/// Uses per square cell of an exemplar `width × height` (in the caller's
/// coordinate units).
pub(crate) struct Occupancy {
    cell: f32,
    cols: u32,
    rows: u32,
    counts: Vec<u32>,
    /// The count of an evenly used cell (the caller sets it).
    pub(crate) expected: f32,
}

impl Occupancy {
    /// No uses yet; cells of side `cell` (at least 1); `expected` 1.
    pub(crate) fn new(width: f32, height: f32, cell: f32) -> Self {
        let cell = cell.max(1.0);
        let cols = ((width / cell).ceil() as u32).max(1);
        let rows = ((height / cell).ceil() as u32).max(1);
        Self {
            cell,
            cols,
            rows,
            counts: vec![0; cols as usize * rows as usize],
            expected: 1.0,
        }
    }

    /// Number of cells.
    pub(crate) fn cells(&self) -> usize {
        self.counts.len()
    }

    /// The cell of `c` (coordinates past the exemplar go to its edge cells).
    #[inline]
    pub(crate) fn index(&self, c: Vec2) -> usize {
        let x = ((c.x / self.cell) as u32).min(self.cols - 1);
        let y = ((c.y / self.cell) as u32).min(self.rows - 1);
        y as usize * self.cols as usize + x as usize
    }

    /// One more use at `c`.
    pub(crate) fn add(&mut self, c: Vec2) {
        let i = self.index(c);
        self.counts[i] += 1;
    }

    /// A use moves from `from` (none: a new use) to `to`.
    pub(crate) fn moved(&mut self, from: Option<Vec2>, to: Vec2) {
        let b = self.index(to);
        if let Some(f) = from {
            let a = self.index(f);
            if a == b {
                return;
            }
            self.counts[a] = self.counts[a].saturating_sub(1);
        }
        self.counts[b] += 1;
    }

    /// Uses of `c`'s cell by others than the one at `here`, in shares of
    /// `expected`.
    #[inline]
    pub(crate) fn share(&self, c: Vec2, here: Option<Vec2>) -> f32 {
        let i = self.index(c);
        let own = u32::from(here.is_some_and(|h| self.index(h) == i));
        self.counts[i].saturating_sub(own) as f32 / self.expected
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_move_between_cells_and_exclude_the_asker() {
        let mut occ = Occupancy::new(32.0, 20.0, 8.0);
        assert_eq!(occ.cells(), 4 * 3);
        let (a, b) = (Vec2::new(1.0, 1.0), Vec2::new(31.0, 19.0));
        assert_eq!(occ.index(b), 11);
        assert_eq!(occ.index(Vec2::new(99.0, -5.0)), 3);
        occ.add(a);
        occ.add(a);
        occ.expected = 2.0;
        assert_eq!(occ.share(a, None), 1.0);
        assert_eq!(occ.share(a, Some(a)), 0.5);
        occ.moved(Some(a), b);
        assert_eq!(occ.share(a, None), 0.5);
        assert_eq!(occ.share(b, None), 0.5);
        occ.moved(Some(b), Vec2::new(30.0, 18.0));
        assert_eq!(occ.share(b, None), 0.5);
        occ.moved(None, b);
        assert_eq!(occ.share(b, None), 1.0);
    }
}
