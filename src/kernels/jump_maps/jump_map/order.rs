//! Pixel orders for synthesis (Zelinka & Garland 2004, §5.3): scanline,
//! serpentine and Hilbert path, for any `width × height`.
//!
//! The Hilbert order follows the smallest power-of-two Hilbert curve covering
//! the image and skips locations outside it, as the paper does. It is a
//! stateful iterator (the paper's fix for the slow stateless version): an
//! explicit stack of quadrants, descending the curve's recursion and pruning
//! whole quadrants that lie outside the image, so each pixel costs O(1)
//! amortised and nothing is allocated per pixel. Inside a power-of-two square
//! consecutive pixels are 4-neighbours.

/// Which order pixels are synthesized in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum PixelOrder {
    /// Left to right, top to bottom.
    Scanline,
    /// Rows alternate left-to-right and right-to-left, top to bottom.
    Serpentine,
    /// The Hilbert path (the paper's choice: best patch shapes).
    #[default]
    Hilbert,
}

impl PixelOrder {
    /// Iterator over all `(x, y)` of a `width × height` image in this order;
    /// each pixel exactly once. Empty when either size is 0. Precondition:
    /// both sizes at most 2³¹.
    pub fn iter(self, width: u32, height: u32) -> PixelOrderIter {
        let inner = if width == 0 || height == 0 {
            Inner::Done
        } else {
            match self {
                PixelOrder::Scanline => Inner::Rows {
                    x: 0,
                    y: 0,
                    serpentine: false,
                },
                PixelOrder::Serpentine => Inner::Rows {
                    x: 0,
                    y: 0,
                    serpentine: true,
                },
                PixelOrder::Hilbert => Inner::Hilbert(Box::new(HilbertIter::new(width, height))),
            }
        };
        PixelOrderIter {
            width,
            height,
            inner,
        }
    }
}

/// Iterator returned by [`PixelOrder::iter`].
#[derive(Clone, Debug)]
pub struct PixelOrderIter {
    width: u32,
    height: u32,
    inner: Inner,
}

#[derive(Clone, Debug)]
enum Inner {
    Done,
    Rows { x: u32, y: u32, serpentine: bool },
    Hilbert(Box<HilbertIter>),
}

impl Iterator for PixelOrderIter {
    type Item = (u32, u32);

    #[inline]
    fn next(&mut self) -> Option<(u32, u32)> {
        match &mut self.inner {
            Inner::Done => None,
            Inner::Rows { x, y, serpentine } => {
                if *y >= self.height {
                    return None;
                }
                let px = if *serpentine && *y % 2 == 1 {
                    self.width - 1 - *x
                } else {
                    *x
                };
                let out = (px, *y);
                *x += 1;
                if *x == self.width {
                    *x = 0;
                    *y += 1;
                }
                Some(out)
            }
            Inner::Hilbert(h) => h.next(),
        }
    }
}

/// One quadrant on the Hilbert stack.
#[derive(Clone, Copy, Debug, Default)]
struct Frame {
    x0: u32,
    y0: u32,
    /// log2 of the quadrant's side.
    level: u8,
    /// Orientation: an element of the Klein four-group {identity, transpose,
    /// anti-transpose, half-turn} = {0, 1, 2, 3}; composition is XOR.
    state: u8,
    /// Next child to visit, 0..4.
    child: u8,
}

/// Sub-quadrant positions of the base curve, in visiting order: it enters at
/// the (0, 0) corner and leaves at (1, 0).
const BASE_POS: [(u32, u32); 4] = [(0, 0), (0, 1), (1, 1), (1, 0)];
/// Orientation of each sub-curve relative to its parent: transpose, identity,
/// identity, anti-transpose (the L-system of §5.3).
const BASE_STATE: [u8; 4] = [1, 0, 0, 2];

#[inline]
fn transform(state: u8, (x, y): (u32, u32)) -> (u32, u32) {
    match state {
        0 => (x, y),
        1 => (y, x),
        2 => (1 - y, 1 - x),
        _ => (1 - x, 1 - y),
    }
}

/// Stateful Hilbert traversal of a `width × height` image.
#[derive(Clone, Debug)]
pub struct HilbertIter {
    width: u32,
    height: u32,
    stack: [Frame; 33],
    depth: usize,
}

impl HilbertIter {
    /// Starts the traversal. Precondition: `width, height >= 1`.
    pub fn new(width: u32, height: u32) -> Self {
        let side = width.max(height).next_power_of_two();
        let mut stack = [Frame::default(); 33];
        stack[0] = Frame {
            x0: 0,
            y0: 0,
            level: side.trailing_zeros() as u8,
            state: 0,
            child: 0,
        };
        Self {
            width,
            height,
            stack,
            depth: 1,
        }
    }
}

impl Iterator for HilbertIter {
    type Item = (u32, u32);

    #[inline]
    fn next(&mut self) -> Option<(u32, u32)> {
        while self.depth > 0 {
            let top = &mut self.stack[self.depth - 1];
            if top.level == 0 {
                // A single pixel (only the root of a 1×1 image).
                self.depth -= 1;
                return Some((top.x0, top.y0));
            }
            if top.child == 4 {
                self.depth -= 1;
                continue;
            }
            let i = top.child as usize;
            top.child += 1;
            let (qx, qy) = transform(top.state, BASE_POS[i]);
            let half = 1u32 << (top.level - 1);
            let (cx, cy) = (top.x0 + qx * half, top.y0 + qy * half);
            if cx >= self.width || cy >= self.height {
                continue;
            }
            if half == 1 {
                return Some((cx, cy));
            }
            let f = Frame {
                x0: cx,
                y0: cy,
                level: top.level - 1,
                state: top.state ^ BASE_STATE[i],
                child: 0,
            };
            self.stack[self.depth] = f;
            self.depth += 1;
        }
        None
    }
}
