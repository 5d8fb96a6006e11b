//! The memory side of the stage contract: the input sizes a stage's
//! estimate scales with ([`InputSizes`]) and the estimate itself
//! ([`MemoryEstimate`], with the ways out of it, [`Fit`]). The pipeline
//! checks the estimates against the machine's memory limit before any work
//! (`pipeline::memory_budget`).

/// Sizes of the run's input that estimates scale with. Before the input is
/// loaded (validation) every size is 0 and `loaded` false: estimates are
/// then lower bounds.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct InputSizes {
    /// Whether the sizes are the loaded input's.
    pub loaded: bool,
    /// Vertices of the input mesh.
    pub vertices: u64,
    /// Faces (polygons) of the input mesh.
    pub faces: u64,
    /// Triangles of its fan triangulation.
    pub triangles: u64,
    /// Its surface area, world units².
    pub area: f64,
    /// Exemplar width, pixels.
    pub exemplar_width: u32,
    /// Exemplar height, pixels.
    pub exemplar_height: u32,
    /// Exemplar channels.
    pub exemplar_channels: u32,
    /// Channels of the exemplar's material maps (normal 3, roughness 1,
    /// height 1), summed.
    pub map_channels: u32,
    /// `[input] texture_scale` resolved: exemplar pixels per world unit.
    pub texels_per_unit: f64,
    /// Bounding-box diagonal of the input mesh, world units.
    pub diagonal: f64,
    /// Whether the exemplar tiles (`[input] exemplar_wrap = "repeat"`).
    pub exemplar_repeats: bool,
}

impl InputSizes {
    /// These sizes with the active mesh replaced by a closed triangle mesh
    /// of `vertices` vertices (about two triangles per vertex) over the same
    /// surface: what the stages after a retiling or a subdivision see.
    pub fn with_mesh(&self, vertices: u64) -> Self {
        Self {
            vertices,
            faces: vertices.saturating_mul(2),
            triangles: vertices.saturating_mul(2),
            ..*self
        }
    }

    /// Exemplar pixels.
    pub fn exemplar_pixels(&self) -> u64 {
        u64::from(self.exemplar_width) * u64::from(self.exemplar_height)
    }

    /// Bytes the loaded input holds for the whole run: the exemplar and its
    /// maps (`f32` per channel), the mesh (positions, corners, face starts).
    pub fn resident_bytes(&self) -> u64 {
        let image =
            self.exemplar_pixels() * u64::from(self.exemplar_channels + self.map_channels) * 4;
        let mesh = self.vertices * 12 + (self.triangles + 2 * self.faces) * 4 + self.faces * 4;
        image + mesh
    }

    /// Vertices a surface of `area` needs for one vertex per exemplar pixel²
    /// at the run's texture scale
    /// ([`crate::world::TextureScale::vertices_for_area`]).
    pub fn vertices_for_area(&self, area: f64) -> f64 {
        area * self.texels_per_unit * self.texels_per_unit
    }
}

/// The largest value of a parameter within a number of bytes, as the user
/// would write it (`None`: not even the smallest).
type Largest = Box<dyn Fn(u64) -> Option<String>>;

/// One way out of an estimate over the limit: a parameter and the largest
/// value of it that fits.
pub struct Fit {
    /// The parameter, as a config names it (`width x height`, `size`).
    pub param: String,
    /// Between the parameter and its value in a message: ` = `.
    pub separator: &'static str,
    largest: Largest,
}

impl Fit {
    /// The largest value of an integer parameter in `range` whose
    /// `bytes_at` is within a budget (`bytes_at` non-decreasing), shown by
    /// `show`.
    pub fn growing(
        param: impl Into<String>,
        range: (u64, u64),
        bytes_at: impl Fn(u64) -> u64 + 'static,
        show: impl Fn(u64) -> String + 'static,
    ) -> Self {
        Self {
            param: param.into(),
            separator: " = ",
            largest: Box::new(move |budget| {
                let (mut lo, mut hi) = range;
                if bytes_at(lo) > budget {
                    return None;
                }
                while lo < hi {
                    let mid = lo + (hi - lo).div_ceil(2);
                    if bytes_at(mid) <= budget {
                        lo = mid;
                    } else {
                        hi = mid - 1;
                    }
                }
                Some(show(lo))
            }),
        }
    }

    /// The largest of `values` (in increasing order) whose `bytes_at` is
    /// within a budget, for a parameter whose estimate need not grow with
    /// it (a scan rather than a bisection), shown by `show`.
    pub fn scan(
        param: impl Into<String>,
        values: Vec<u64>,
        bytes_at: impl Fn(u64) -> u64 + 'static,
        show: impl Fn(u64) -> String + 'static,
    ) -> Self {
        Self {
            param: param.into(),
            separator: " = ",
            largest: Box::new(move |budget| {
                values
                    .iter()
                    .rev()
                    .find(|&&v| bytes_at(v) <= budget)
                    .map(|&v| show(v))
            }),
        }
    }

    /// A fit computed by `largest` (the value within a budget, as written).
    pub fn with(
        param: impl Into<String>,
        largest: impl Fn(u64) -> Option<String> + 'static,
    ) -> Self {
        Self {
            param: param.into(),
            separator: " = ",
            largest: Box::new(largest),
        }
    }

    /// Written `PARAM SEPARATOR VALUE` in messages (` = ` by default).
    pub fn separated(mut self, separator: &'static str) -> Self {
        self.separator = separator;
        self
    }

    /// The largest value within `budget` bytes, as written in a config.
    pub fn largest_within(&self, budget: u64) -> Option<String> {
        (self.largest)(budget)
    }
}

/// A stage's estimate of one large allocation (or of its peak while a
/// parameter's work runs).
pub struct MemoryEstimate {
    /// The parameter it grows with, as a config names it.
    pub param: &'static str,
    /// Its value, as written (`8192x8192`, `[31, 31, 31]`).
    pub value: String,
    /// What is allocated, for messages.
    pub what: String,
    /// Estimated bytes.
    pub bytes: u64,
    /// Ways out when over the limit, the parameter's own first.
    pub fits: Vec<Fit>,
}

impl MemoryEstimate {
    /// An estimate of `bytes_at(value)` growing with the integer parameter
    /// `param` in `range`, shown by `show`.
    pub fn growing(
        param: &'static str,
        what: impl Into<String>,
        value: u64,
        range: (u64, u64),
        bytes_at: impl Fn(u64) -> u64 + Clone + 'static,
        show: impl Fn(u64) -> String + Clone + 'static,
    ) -> Self {
        Self {
            param,
            value: show(value),
            what: what.into(),
            bytes: bytes_at(value),
            fits: vec![Fit::growing(param, range, bytes_at, show)],
        }
    }

    /// [`Self::growing`] for an image of `width × height` pixels (`param`
    /// names both, e.g. `width x height`): the largest size that fits keeps
    /// the aspect ratio, its longer side in `1..=max_side`.
    pub fn image(
        param: &'static str,
        what: impl Into<String>,
        (width, height): (u32, u32),
        max_side: u32,
        bytes_at: impl Fn(u64, u64) -> u64 + Clone + 'static,
    ) -> Self {
        let (w, h) = (u64::from(width.max(1)), u64::from(height.max(1)));
        let long = w.max(h);
        let dims = move |side: u64| {
            let scale = |d: u64| ((d as f64 * side as f64 / long as f64).round() as u64).max(1);
            (scale(w), scale(h))
        };
        let show = move |side: u64| {
            let (a, b) = dims(side);
            format!("{a}x{b}")
        };
        let now = bytes_at(w, h);
        let bytes = move |side: u64| {
            let (a, b) = dims(side);
            bytes_at(a, b)
        };
        Self {
            param,
            value: format!("{width}x{height}"),
            what: what.into(),
            bytes: now,
            fits: vec![Fit::growing(param, (1, u64::from(max_side)), bytes, show)],
        }
    }

    /// The working memory of a stage that keeps a few arrays per vertex of
    /// the mesh it works on (the input mesh, or the one a `retile`,
    /// `subdivide_sqrt2` or `builtin_pyramid` stage before it makes):
    /// `fixed + per_vertex · vertices` bytes, `fixed` being what the stage
    /// holds of the exemplar. The way out is a mesh of fewer vertices.
    /// Empty while the vertex count is unknown (validation without an
    /// explicit count).
    pub fn per_vertex(
        what: impl Into<String>,
        sizes: &InputSizes,
        fixed: u64,
        per_vertex: u64,
    ) -> Vec<Self> {
        if sizes.vertices == 0 {
            return Vec::new();
        }
        vec![Self::growing(
            "vertices",
            what,
            sizes.vertices,
            (1, 1 << 40),
            move |v| fixed.saturating_add(v.saturating_mul(per_vertex)),
            |v| v.to_string(),
        )]
    }

    /// Another way out, tried after the parameter's own.
    pub fn or(mut self, fit: Fit) -> Self {
        self.fits.push(fit);
        self
    }
}

/// Shows a byte count in GiB (two decimals), else MiB, else KiB.
pub fn show_bytes(bytes: u64) -> String {
    let b = bytes as f64;
    if bytes >= 1 << 40 {
        format!("{:.2} TiB", b / (1u64 << 40) as f64)
    } else if bytes >= 1 << 30 {
        format!("{:.2} GiB", b / (1u64 << 30) as f64)
    } else if bytes >= 1 << 20 {
        format!("{:.1} MiB", b / (1u64 << 20) as f64)
    } else {
        format!("{:.0} KiB", b / 1024.0)
    }
}

/// Bytes per vertex of a builtin mesh over a whole pipeline: positions,
/// faces (two triangles per grid vertex), topology (edges, one-rings,
/// vertex→faces), tangent frames, scales, colours, source texels, the
/// neighbourhood vectors of the matching stages, and the copies later stages
/// and the exporter make (≈ 60 `f32`/`u32` arrays of 1–3 values). A coarse
/// upper bound: what a stage adds is its own estimate.
pub const BYTES_PER_MESH_VERTEX: u64 = 1024;
