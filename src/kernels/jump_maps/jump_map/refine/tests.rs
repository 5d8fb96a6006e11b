use super::*;

/// A `size`² exemplar of horizontal boards: a dark line every 8 rows,
/// grain varying along x and between boards.
fn boards(size: u32) -> Image {
    let mut img = Image::new(size, size, 3);
    for y in 0..size {
        for x in 0..size {
            let line = if y % 8 == 0 { 0.1 } else { 0.6 };
            let grain = 0.2 * ((x as f32 * 0.37 + (y / 8) as f32 * 1.3).sin());
            img.pixel_mut(x, y)
                .copy_from_slice(&[line + grain, line, 0.5 + 0.01 * y as f32]);
        }
    }
    img
}

/// A `w × h` output: the left half copies the exemplar from `(0, 8)`,
/// the right half continues it but two rows down (a board edge off by
/// two pixels at the seam).
fn misaligned(w: u32, h: u32, ex: &Image) -> SourceMap {
    map_of(w, h, ex, |x, y| TexelCoord {
        x: x + 4,
        y: y + if x < w / 2 { 8 } else { 10 },
    })
}

/// A `w × h` source map over `ex` with `source(x, y)` at each pixel.
fn map_of(w: u32, h: u32, ex: &Image, source: impl Fn(u32, u32) -> TexelCoord) -> SourceMap {
    SourceMap {
        width: w,
        height: h,
        exemplar_width: ex.width,
        exemplar_height: ex.height,
        texels: (0..w * h).map(|i| source(i % w, i / w)).collect(),
    }
}

#[test]
fn a_misaligned_region_is_moved_to_continue_its_neighbour() {
    let ex = boards(64);
    let mut s = misaligned(32, 32, &ex);
    let report = align_regions(&mut s, &ex, false, ALIGN_SWEEPS, &Progress::hidden());
    assert_eq!(report.regions, 2, "{report:?}");
    assert!(report.shifted[0] >= 1, "{report:?}");
    // Every pair across the seam now continues: one copied piece.
    for y in 0..32usize {
        let (a, b) = (s.texels[y * 32 + 15], s.texels[y * 32 + 16]);
        assert_eq!((b.x, b.y), (a.x + 1, a.y), "row {y}");
    }
}

#[test]
fn alignment_never_joins_a_copy_of_a_third_of_the_exemplar() {
    // The same two halves (512 pixels each) over a 36² exemplar: joined
    // they would copy 1 024 pixels, more than a third of its 1 296.
    let ex = boards(36);
    let mut s = misaligned(32, 16, &ex);
    let before = s.texels.clone();
    let report = align_regions(&mut s, &ex, false, ALIGN_SWEEPS, &Progress::hidden());
    assert_eq!(report.regions, 2, "{report:?}");
    let seam_continues = (0..16usize).all(|y| {
        let (a, b) = (s.texels[y * 32 + 15], s.texels[y * 32 + 16]);
        (b.x, b.y) == (a.x + 1, a.y)
    });
    assert!(!seam_continues, "the halves were joined: {report:?}");
    // Any shift it made still lowered the border cost, so the output
    // differs from the start only where a half moved as a whole.
    let moved: Vec<bool> = s.texels.iter().zip(&before).map(|(a, b)| a != b).collect();
    for half in [0usize, 16] {
        let m: Vec<bool> = (0..16)
            .flat_map(|y| (half..half + 16).map(move |x| y * 32 + x))
            .map(|i| moved[i])
            .collect();
        assert!(m.iter().all(|&v| v == m[0]), "a half moved in part");
    }
}

/// Copied regions of `s` (4-connected pixels whose sources continue
/// each other), as their areas, largest first.
fn region_areas(s: &SourceMap) -> Vec<usize> {
    let (w, h) = (s.width as usize, s.height as usize);
    let mut parent: Vec<u32> = (0..(w * h) as u32).collect();
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            for (j, dx, dy) in [(i + 1, 1, 0), (i + w, 0, 1)] {
                if (dx == 1 && x + 1 == w) || (dy == 1 && y + 1 == h) {
                    continue;
                }
                let (a, b) = (s.texels[i], s.texels[j]);
                if (b.x, b.y) == (a.x + dx, a.y + dy) {
                    let (ra, rb) = (find(&mut parent, i as u32), find(&mut parent, j as u32));
                    parent[ra.max(rb) as usize] = ra.min(rb);
                }
            }
        }
    }
    let mut area = vec![0usize; w * h];
    for i in 0..w * h {
        area[find(&mut parent, i as u32) as usize] += 1;
    }
    area.retain(|&a| a > 0);
    area.sort_unstable_by(|a, b| b.cmp(a));
    area
}

/// Two pieces of 15 × `h` pixels copying one 36² exemplar at one
/// offset, with a column of pixels from elsewhere between them: each
/// column pixel's best candidate is the pieces' continuation (it matches
/// both sides exactly), which joins them.
fn split_by_a_column(h: u32, ex: &Image) -> SourceMap {
    map_of(31, h, ex, |x, y| {
        if x == 15 {
            TexelCoord {
                x: 30,
                y: (y * 7) % 30,
            }
        } else {
            TexelCoord { x: x + 2, y: y + 4 }
        }
    })
}

#[test]
fn seam_passes_never_join_pieces_into_a_copy_of_a_third_of_the_exemplar() {
    let ex = boards(36);
    let large = (36usize * 36).div_ceil(3);
    // 8 rows: joined they copy 248 pixels, under a third of 1 296, and
    // the passes join them (the column takes the continuation).
    let mut small = split_by_a_column(8, &ex);
    refine_seams(&mut small, &ex, false, 3, 2, &Progress::hidden());
    assert_eq!(region_areas(&small), vec![31 * 8], "not joined");
    // 20 rows: joined they would copy 620 pixels, a third or more; the
    // guard keeps them apart.
    let mut tall = split_by_a_column(20, &ex);
    refine_seams(&mut tall, &ex, false, 3, 2, &Progress::hidden());
    let areas = region_areas(&tall);
    assert!(areas[0] < large, "a copy of {} pixels: {areas:?}", areas[0]);
}

/// A 32² exemplar of smooth, position-dependent colour (every window
/// unique).
fn exemplar() -> Image {
    let mut img = Image::new(32, 32, 3);
    for y in 0..32u32 {
        for x in 0..32u32 {
            let (fx, fy) = (x as f32 / 31.0, y as f32 / 31.0);
            img.pixel_mut(x, y)
                .copy_from_slice(&[fx, fy, 0.5 + 0.5 * (6.0 * fx + 4.0 * fy).sin()]);
        }
    }
    img
}

/// The refinement's objective over every pixel: the squared colour
/// differences between the exemplar window at each pixel's source and
/// the output around it (5 × 5, centre left out).
fn window_error(s: &SourceMap, ex: &Image) -> f32 {
    let (w, h) = (s.width as i64, s.height as i64);
    let mut e = 0.0;
    for y in 0..h {
        for x in 0..w {
            let p = s.texels[(y * w + x) as usize];
            for dy in -2i64..=2 {
                for dx in -2i64..=2 {
                    let (qx, qy) = (x + dx, y + dy);
                    let (cx, cy) = (p.x as i64 + dx, p.y as i64 + dy);
                    if (dx, dy) == (0, 0)
                        || qx < 0
                        || qy < 0
                        || qx >= w
                        || qy >= h
                        || cx < 0
                        || cy < 0
                        || cx >= ex.width as i64
                        || cy >= ex.height as i64
                    {
                        continue;
                    }
                    let q = s.texels[(qy * w + qx) as usize];
                    let (a, b) = (ex.pixel(cx as u32, cy as u32), ex.pixel(q.x, q.y));
                    e += (0..3).map(|i| (a[i] - b[i]) * (a[i] - b[i])).sum::<f32>();
                }
            }
        }
    }
    e
}

#[test]
fn seam_pixels_take_a_neighbours_continuation_and_the_window_error_falls() {
    let ex = exemplar();
    // A 16² output: the left half copies from (2, 2), the right half
    // from (12, 9), so a vertical seam runs down the middle.
    let (w, h) = (16u32, 16u32);
    let origin = |x: u32| if x < 8 { (2, 2) } else { (12 - 8, 9) };
    let texels: Vec<TexelCoord> = (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let (ox, oy) = origin(x);
            TexelCoord {
                x: ox + x,
                y: oy + y,
            }
        })
        .collect();
    let mut s = SourceMap {
        width: w,
        height: h,
        exemplar_width: 32,
        exemplar_height: 32,
        texels,
    };
    let before = window_error(&s, &ex);
    let report = refine_seams(&mut s, &ex, false, 3, 2, &Progress::hidden());
    let after = window_error(&s, &ex);
    assert!(report.visited[0] > 0 && report.moved[0] > 0, "{report:?}");
    assert!(after < before, "window error {before} -> {after}");
    // Every source still continues one of the two patches.
    for (i, t) in s.texels.iter().enumerate() {
        let (x, y) = (i as u32 % w, i as u32 / w);
        let from_left = (t.x as i64 - x as i64, t.y as i64 - y as i64) == (2, 2);
        let from_right = (t.x as i64 - x as i64, t.y as i64 - y as i64) == (4, 9);
        assert!(from_left || from_right, "pixel ({x}, {y}) took {t:?}");
    }
    // Nothing to refine in one patch.
    let mut whole = s.clone();
    whole.texels = (0..w * h)
        .map(|i| TexelCoord {
            x: 2 + i % w,
            y: 2 + i / w,
        })
        .collect();
    let r = refine_seams(&mut whole, &ex, false, 3, 2, &Progress::hidden());
    assert_eq!(r.visited, vec![0]);
}

#[test]
fn the_pyramid_keeps_every_source_in_the_exemplar_and_lowers_the_window_error() {
    let ex = exemplar();
    // A 32² output of four quadrants copied from different places.
    let (w, h) = (32u32, 32u32);
    let origin = |x: u32, y: u32| match (x < 16, y < 16) {
        (true, true) => (1, 2),
        (false, true) => (9, 3),
        (true, false) => (12, 11),
        (false, false) => (3, 14),
    };
    let texels: Vec<TexelCoord> = (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let (ox, oy) = origin(x, y);
            TexelCoord {
                x: (ox + x % 16).min(31),
                y: (oy + y % 16).min(31),
            }
        })
        .collect();
    let s0 = SourceMap {
        width: w,
        height: h,
        exemplar_width: 32,
        exemplar_height: 32,
        texels,
    };
    // No halving: exactly the single-scale refinement.
    let (mut a, mut b) = (s0.clone(), s0.clone());
    let ra = refine_seams(&mut a, &ex, false, 3, 2, &Progress::hidden());
    let rb = refine_seams_pyramid(&mut b, &ex, false, 3, 2, 0, &Progress::hidden());
    assert_eq!((a.texels.clone(), ra), (b.texels, rb));
    // One halving: valid sources, and no worse than before.
    let mut c = s0.clone();
    refine_seams_pyramid(&mut c, &ex, false, 3, 2, 1, &Progress::hidden());
    assert!(c.texels.iter().all(|t| t.x < 32 && t.y < 32));
    let (before, after) = (window_error(&s0, &ex), window_error(&c, &ex));
    assert!(after < before, "window error {before} -> {after}");
}
