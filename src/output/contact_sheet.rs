//! Contact sheets: images side by side in one row, each with a text label
//! underneath, as one RGB [`Image`] (the quality benchmark's
//! `sheet_<texture>.png`: exemplar | peer | every method).
//!
//! This builds the picture only; writing it goes through
//! [`super::write_png`] like every other image.

use super::bitmap_font::{GLYPH_HEIGHT, GLYPH_WIDTH, glyph};
use crate::image::Image;

/// One tile of a sheet: an image (any channel count, values in `[0, 1]`) and
/// its label (ASCII; `\n` starts a new line; other characters draw as `?`).
#[derive(Clone, Copy, Debug)]
pub struct SheetTile<'a> {
    /// The picture.
    pub image: &'a Image,
    /// Text drawn under the picture.
    pub label: &'a str,
}

/// How a sheet is laid out and coloured.
#[derive(Clone, Debug, PartialEq)]
pub struct SheetLayout {
    /// Height every tile is scaled to (nearest neighbour, aspect kept); `None`
    /// means the tallest tile's height, so tiles of equal size are copied
    /// pixel for pixel.
    pub tile_height: Option<u32>,
    /// Pixels between tiles and around the sheet; default 8.
    pub gap: u32,
    /// Screen pixels per font pixel (a glyph is `5·scale × 7·scale`), at
    /// least 1; default 2.
    pub font_scale: u32,
    /// RGB of the background; default dark grey.
    pub background: [f32; 3],
    /// RGB of the label text; default white.
    pub ink: [f32; 3],
}

impl Default for SheetLayout {
    fn default() -> Self {
        Self {
            tile_height: None,
            gap: 8,
            font_scale: 2,
            background: [0.15, 0.15, 0.15],
            ink: [1.0, 1.0, 1.0],
        }
    }
}

/// A rectangle of the sheet, in sheet pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SheetRect {
    /// Left column.
    pub x: u32,
    /// Top row.
    pub y: u32,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
}

/// A built sheet and where each tile and label went.
#[derive(Clone, Debug)]
pub struct ContactSheet {
    /// The sheet, RGB (3 channels).
    pub image: Image,
    /// Where each tile's (scaled) picture is, in input order.
    pub tiles: Vec<SheetRect>,
    /// Each tile's label strip (the full slot width under the picture).
    pub labels: Vec<SheetRect>,
}

/// Lays `tiles` out left to right: each scaled to a common height, its label
/// under it; a slot is as wide as the wider of its picture and its label
/// (plus a glyph's width of margin on either side of the label).
/// An empty `tiles` gives a sheet of only the margins.
pub fn contact_sheet(tiles: &[SheetTile<'_>], layout: &SheetLayout) -> ContactSheet {
    let scale = layout.font_scale.max(1);
    let gap = layout.gap;
    let height = layout
        .tile_height
        .unwrap_or_else(|| tiles.iter().map(|t| t.image.height).max().unwrap_or(1))
        .max(1);
    let pictures: Vec<Image> = tiles
        .iter()
        .map(|t| scale_to_height(&t.image.to_rgb(), height))
        .collect();
    let line_height = (GLYPH_HEIGHT + 2) * scale;
    // A glyph's width of space on either side keeps neighbouring labels apart.
    let label_margin = 2 * GLYPH_WIDTH * scale;
    let label_height = tiles
        .iter()
        .map(|t| t.label.lines().count().max(1) as u32 * line_height)
        .max()
        .unwrap_or(line_height);
    let slot_widths: Vec<u32> = tiles
        .iter()
        .zip(&pictures)
        .map(|(t, p)| p.width.max(text_width(t.label, scale) + label_margin))
        .collect();
    let width = gap + slot_widths.iter().map(|w| w + gap).sum::<u32>();
    let sheet_height = gap + height + gap / 2 + label_height + gap / 2;
    let mut image = Image::new(width, sheet_height, 3);
    for px in image.data.chunks_exact_mut(3) {
        px.copy_from_slice(&layout.background);
    }
    let mut tile_rects = Vec::with_capacity(tiles.len());
    let mut label_rects = Vec::with_capacity(tiles.len());
    let mut x0 = gap;
    for ((tile, picture), &slot) in tiles.iter().zip(&pictures).zip(&slot_widths) {
        let px0 = x0 + (slot - picture.width) / 2;
        for y in 0..picture.height {
            for x in 0..picture.width {
                image
                    .pixel_mut(px0 + x, gap + y)
                    .copy_from_slice(picture.pixel(x, y));
            }
        }
        tile_rects.push(SheetRect {
            x: px0,
            y: gap,
            width: picture.width,
            height: picture.height,
        });
        let label_y = gap + height + gap / 2;
        for (i, line) in tile.label.lines().enumerate() {
            let lx = x0 + (slot - text_width(line, scale)) / 2;
            let ly = label_y + i as u32 * line_height + scale;
            draw_text(&mut image, lx, ly, line, scale, layout.ink);
        }
        label_rects.push(SheetRect {
            x: x0,
            y: label_y,
            width: slot,
            height: label_height,
        });
        x0 += slot + gap;
    }
    ContactSheet {
        image,
        tiles: tile_rects,
        labels: label_rects,
    }
}

/// Width in pixels of the widest line of `text` at `scale` (one font pixel of
/// spacing between glyphs, none after the last).
pub fn text_width(text: &str, scale: u32) -> u32 {
    text.lines()
        .map(|l| l.chars().count() as u32)
        .max()
        .unwrap_or(0)
        .checked_mul((GLYPH_WIDTH + 1) * scale.max(1))
        .map_or(u32::MAX, |w| w.saturating_sub(scale.max(1)))
}

/// Draws one line of `text` with its top-left corner at (`x`, `y`) in
/// `colour` (RGB; the first three channels of `img`); what falls outside the
/// image is clipped.
pub fn draw_text(img: &mut Image, x: u32, y: u32, text: &str, scale: u32, colour: [f32; 3]) {
    let scale = scale.max(1);
    let c = (img.channels as usize).min(3);
    for (i, ch) in text.chars().enumerate() {
        let gx = x as u64 + i as u64 * u64::from((GLYPH_WIDTH + 1) * scale);
        for (row, bits) in glyph(ch).iter().enumerate() {
            for col in 0..GLYPH_WIDTH {
                if bits & (1 << (GLYPH_WIDTH - 1 - col)) == 0 {
                    continue;
                }
                for dy in 0..scale {
                    for dx in 0..scale {
                        let px = gx + u64::from(col * scale + dx);
                        let py = u64::from(y) + u64::from(row as u32 * scale + dy);
                        if px < u64::from(img.width) && py < u64::from(img.height) {
                            img.pixel_mut(px as u32, py as u32)[..c].copy_from_slice(&colour[..c]);
                        }
                    }
                }
            }
        }
    }
}

/// Nearest-neighbour scaling to `height` rows, the width scaled by the same
/// factor (rounded, at least 1); an image already `height` tall is returned
/// unchanged.
fn scale_to_height(img: &Image, height: u32) -> Image {
    if img.height == height || img.width == 0 || img.height == 0 {
        return img.clone();
    }
    let width = ((u64::from(img.width) * u64::from(height) + u64::from(img.height) / 2)
        / u64::from(img.height))
    .max(1) as u32;
    let mut out = Image::new(width, height, img.channels);
    for y in 0..height {
        let sy = ((u64::from(y) * u64::from(img.height)) / u64::from(height)) as u32;
        for x in 0..width {
            let sx = ((u64::from(x) * u64::from(img.width)) / u64::from(width)) as u32;
            out.pixel_mut(x, y).copy_from_slice(img.pixel(sx, sy));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gradient(width: u32, height: u32) -> Image {
        let mut img = Image::new(width, height, 3);
        for y in 0..height {
            for x in 0..width {
                let p = img.pixel_mut(x, y);
                p[0] = x as f32 / width as f32;
                p[1] = y as f32 / height as f32;
                p[2] = 0.5;
            }
        }
        img
    }

    #[test]
    fn tiles_of_equal_size_are_copied_exactly() {
        let a = gradient(20, 16);
        let b = gradient(20, 16);
        let sheet = contact_sheet(
            &[
                SheetTile {
                    image: &a,
                    label: "a",
                },
                SheetTile {
                    image: &b,
                    label: "b",
                },
            ],
            &SheetLayout::default(),
        );
        assert_eq!(sheet.tiles.len(), 2);
        for (r, img) in sheet.tiles.iter().zip([&a, &b]) {
            assert_eq!((r.width, r.height), (20, 16), "not scaled");
            for y in 0..16 {
                for x in 0..20 {
                    assert_eq!(
                        sheet.image.pixel(r.x + x, r.y + y),
                        img.pixel(x, y),
                        "tile pixel ({x}, {y}) copied"
                    );
                }
            }
        }
        assert!(
            sheet.tiles[0].x + 20 <= sheet.tiles[1].x,
            "tiles do not overlap"
        );
    }

    #[test]
    fn label_text_draws_ink_in_the_label_strip_only_where_there_is_text() {
        let a = gradient(64, 32);
        let layout = SheetLayout::default();
        let count_ink = |label: &str| {
            let sheet = contact_sheet(&[SheetTile { image: &a, label }], &layout);
            let r = sheet.labels[0];
            assert!(
                r.y >= sheet.tiles[0].y + sheet.tiles[0].height,
                "strip under the tile"
            );
            let mut ink = 0;
            for y in r.y..r.y + r.height {
                for x in r.x..r.x + r.width {
                    let p = sheet.image.pixel(x, y);
                    if p != layout.background {
                        assert_eq!(p, layout.ink, "label pixels are ink or background");
                        ink += 1;
                    }
                }
            }
            ink
        };
        assert_eq!(count_ink(""), 0);
        assert_eq!(count_ink("   "), 0, "spaces draw nothing");
        let one = count_ink("I");
        // "I" is 11 font pixels, each 2 × 2.
        assert_eq!(one, 11 * 4);
        assert!(count_ink("jump_pixel") > 10 * one / 2);
    }

    #[test]
    fn tiles_of_different_sizes_scale_to_a_common_height_and_long_labels_widen_the_slot() {
        let small = gradient(8, 8);
        let wide = gradient(40, 20);
        let label = "a long label, wider than the tile";
        let sheet = contact_sheet(
            &[
                SheetTile {
                    image: &small,
                    label,
                },
                SheetTile {
                    image: &wide,
                    label: "w",
                },
            ],
            &SheetLayout::default(),
        );
        assert_eq!(
            (sheet.tiles[0].width, sheet.tiles[0].height),
            (20, 20),
            "8² scaled to the tallest height"
        );
        assert_eq!((sheet.tiles[1].width, sheet.tiles[1].height), (40, 20));
        assert_eq!(sheet.labels[0].width, text_width(label, 2) + 2 * 5 * 2);
        // Nearest neighbour: the scaled tile's pixels are pixels of the original.
        let r = sheet.tiles[0];
        for y in 0..r.height {
            for x in 0..r.width {
                let p = sheet.image.pixel(r.x + x, r.y + y);
                let (sx, sy) = (x * 8 / 20, y * 8 / 20);
                assert_eq!(p, small.pixel(sx, sy));
            }
        }
    }

    #[test]
    fn grey_tiles_become_rgb_and_text_is_clipped_at_the_edge() {
        let grey = Image::from_data(2, 2, 1, vec![0.0, 0.25, 0.5, 1.0]).unwrap();
        let sheet = contact_sheet(
            &[SheetTile {
                image: &grey,
                label: "",
            }],
            &SheetLayout {
                tile_height: Some(2),
                ..SheetLayout::default()
            },
        );
        let r = sheet.tiles[0];
        assert_eq!(sheet.image.pixel(r.x + 1, r.y), &[0.25, 0.25, 0.25]);
        let mut img = Image::new(4, 4, 3);
        draw_text(&mut img, 2, 2, "WWW", 3, [1.0; 3]);
        assert!(img.data.contains(&1.0), "the visible corner is drawn");
    }
}
