//! Text: the embedded font (`DejaVu Sans`), its horizontal metrics read from its own
//! tables ([`FontMetrics`]), and labels laid out with them ([`Pen`]).

use std::sync::OnceLock;

use anyhow::anyhow;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// The font family all text is drawn in: the embedded `DejaVu Sans`, registered under
/// this name; SVG writes it as the `font-family`, so a viewer without it draws sans-serif.
pub(super) const FAMILY: &str = "DejaVu Sans, sans-serif";

/// Registers the embedded font for bitmap text (once per process).
pub(super) fn register_font() -> anyhow::Result<()> {
    static DONE: OnceLock<bool> = OnceLock::new();
    let ok = *DONE.get_or_init(|| {
        plotters::style::register_font(FAMILY, FontStyle::Normal, dejavu::sans::regular()).is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err(anyhow!("the embedded font could not be loaded"))
    }
}

/// Big-endian reads from a font file (`None` past its end).
fn be_u16(d: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_be_bytes([
        *d.get(at)?,
        *d.get(at.checked_add(1)?)?,
    ]))
}

fn be_i16(d: &[u8], at: usize) -> Option<i16> {
    be_u16(d, at).map(|v| i16::from_be_bytes(v.to_be_bytes()))
}

fn be_u32(d: &[u8], at: usize) -> Option<u32> {
    Some(u32::from(be_u16(d, at)?) << 16 | u32::from(be_u16(d, at.checked_add(2)?)?))
}

/// The horizontal metrics of a TrueType font, read from its tables (`head`, `hhea`,
/// `OS/2`, `cmap` format 4, `hmtx`, `kern` format 0): what laying out a line of text
/// needs. Font units; [`FontMetrics::scale`] turns them into pixels the way `ab_glyph`
/// (the rasterizer plotters uses) does: a font size is the ascender-to-descender height.
#[derive(Debug)]
pub(crate) struct FontMetrics {
    data: &'static [u8],
    /// Units per em.
    units_per_em: f32,
    /// Ascender minus descender (`hhea`): the height a font size is in pixels.
    height: f32,
    /// The height of a lowercase `x` (`OS/2`; half an em if the table lacks it).
    x_height: f32,
    /// Offset of the `cmap` subtable of format 4 (Unicode BMP).
    cmap: usize,
    /// Offset of `hmtx` and the number of its long (advance, bearing) records.
    hmtx: usize,
    long_metrics: u16,
    /// Offset of the first kerning pair and the number of pairs (`kern` format 0).
    kern: Option<(usize, usize)>,
}

impl FontMetrics {
    /// Reads the metrics of `data`; `None` if a table is missing or cut short.
    fn read(data: &'static [u8]) -> Option<Self> {
        let table = |tag: &[u8; 4]| {
            (0..usize::from(be_u16(data, 4)?)).find_map(|i| {
                let record = 12 + 16 * i;
                (data.get(record..record + 4)? == tag)
                    .then(|| usize::try_from(be_u32(data, record + 8)?).ok())
                    .flatten()
            })
        };
        let head = table(b"head")?;
        let hhea = table(b"hhea")?;
        let height = f32::from(be_i16(data, hhea + 4)?) - f32::from(be_i16(data, hhea + 6)?);
        let units_per_em = f32::from(be_u16(data, head + 18)?);
        let x_height = table(b"OS/2")
            .filter(|&os2| be_u16(data, os2).is_some_and(|version| version >= 2))
            .and_then(|os2| be_i16(data, os2 + 86))
            .map_or(units_per_em / 2.0, f32::from);
        let cmap = table(b"cmap")?;
        let cmap = (0..usize::from(be_u16(data, cmap + 2)?)).find_map(|i| {
            let record = cmap + 4 + 8 * i;
            let platform = (be_u16(data, record)?, be_u16(data, record + 2)?);
            let sub = cmap + usize::try_from(be_u32(data, record + 4)?).ok()?;
            (matches!(platform, (3, 1) | (0, 3)) && be_u16(data, sub)? == 4).then_some(sub)
        })?;
        let kern = table(b"kern").and_then(|kern| {
            let sub = kern + 4;
            let coverage = be_u16(data, sub + 4)?;
            // Format 0 (high byte), horizontal (bit 0), not cross-stream or minimum.
            (be_u16(data, kern)? == 0 && be_u16(data, kern + 2)? >= 1 && coverage & 0xff0f == 1)
                .then_some((sub + 14, usize::from(be_u16(data, sub + 6)?)))
        });
        (height > 0.0 && units_per_em > 0.0).then_some(Self {
            data,
            units_per_em,
            height,
            x_height,
            cmap,
            hmtx: table(b"hmtx")?,
            long_metrics: be_u16(data, hhea + 34)?.max(1),
            kern,
        })
    }

    /// The metrics of the embedded font.
    pub(crate) fn embedded() -> anyhow::Result<&'static Self> {
        static METRICS: OnceLock<Option<FontMetrics>> = OnceLock::new();
        METRICS
            .get_or_init(|| Self::read(dejavu::sans::regular()))
            .as_ref()
            .ok_or_else(|| anyhow!("the embedded font's metrics could not be read"))
    }

    /// Pixels per font unit at font size `size`.
    pub(crate) fn scale(&self, size: u32) -> f32 {
        // Font sizes are a few dozen pixels: exact in f32.
        #[allow(clippy::cast_precision_loss)]
        let size = size as f32;
        size / self.height
    }

    /// The glyph of `c` (0, the missing glyph, outside the BMP or the font).
    pub(crate) fn glyph(&self, c: char) -> u16 {
        self.glyph_of(u32::from(c)).unwrap_or(0)
    }

    fn glyph_of(&self, c: u32) -> Option<u16> {
        let c = u16::try_from(c).ok()?;
        let d = self.data;
        let sub = self.cmap;
        let seg_x2 = usize::from(be_u16(d, sub + 6)?);
        let seg =
            (0..seg_x2 / 2).find(|&i| be_u16(d, sub + 14 + 2 * i).is_some_and(|end| end >= c))?;
        let start = be_u16(d, sub + 16 + seg_x2 + 2 * seg)?;
        if c < start {
            return None;
        }
        let delta = be_u16(d, sub + 16 + 2 * seg_x2 + 2 * seg)?;
        let range_at = sub + 16 + 3 * seg_x2 + 2 * seg;
        let range = usize::from(be_u16(d, range_at)?);
        if range == 0 {
            return Some(c.wrapping_add(delta));
        }
        let g = be_u16(d, range_at + range + 2 * usize::from(c - start))?;
        (g != 0).then(|| g.wrapping_add(delta))
    }

    /// The advance and the left side bearing of `glyph`, font units.
    pub(crate) fn h_metrics(&self, glyph: u16) -> (f32, f32) {
        let d = self.data;
        let long = usize::from(self.long_metrics);
        let g = usize::from(glyph);
        let advance = be_u16(d, self.hmtx + 4 * g.min(long - 1)).unwrap_or(0);
        let bearing = if g < long {
            be_i16(d, self.hmtx + 4 * g + 2)
        } else {
            be_i16(d, self.hmtx + 4 * long + 2 * (g - long))
        };
        (f32::from(advance), f32::from(bearing.unwrap_or(0)))
    }

    /// The kerning between `left` and `right`, font units.
    pub(crate) fn kerning(&self, left: u16, right: u16) -> f32 {
        let Some((pairs, count)) = self.kern else {
            return 0.0;
        };
        let key = u32::from(left) << 16 | u32::from(right);
        let (mut lo, mut hi) = (0, count);
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            let at = pairs + 6 * mid;
            match be_u32(self.data, at).map(|k| k.cmp(&key)) {
                Some(std::cmp::Ordering::Less) => lo = mid + 1,
                Some(std::cmp::Ordering::Greater) => hi = mid,
                Some(std::cmp::Ordering::Equal) => {
                    return be_i16(self.data, at + 4).map_or(0.0, f32::from);
                }
                None => return 0.0,
            }
        }
        0.0
    }

    /// Where each character of `text` goes: the character, its pen position and its
    /// glyph's left side bearing (font units from the start of the line); and the line's
    /// width.
    pub(super) fn layout(&self, text: &str) -> (Vec<(char, f32, f32)>, f32) {
        let mut pen = 0.0;
        let mut previous = None;
        let mut glyphs = Vec::with_capacity(text.len());
        for c in text.chars() {
            let g = self.glyph(c);
            if let Some(p) = previous {
                pen += self.kerning(p, g);
            }
            let (advance, bearing) = self.h_metrics(g);
            glyphs.push((c, pen, bearing));
            pen += advance;
            previous = Some(g);
        }
        (glyphs, pen)
    }

    /// The width of `text` at font size `size`, pixels (rounded up).
    pub(crate) fn width(&self, text: &str, size: u32) -> i32 {
        px(self.layout(text).1 * self.scale(size)).saturating_add(1)
    }
}

/// A pixel coordinate from a float (saturating; plot coordinates are a few thousand).
pub(super) fn px(v: f32) -> i32 {
    // Saturating by `as`, and the values are far inside i32.
    #[allow(clippy::cast_possible_truncation)]
    let v = v.floor() as i32;
    v
}

/// A line of text to draw.
#[derive(Clone, Copy)]
pub(super) struct Label<'a> {
    pub(super) text: &'a str,
    /// The anchor: where the line's start, middle or end ([`Label::align`]) goes, and its
    /// vertical middle (the middle of a lowercase letter).
    pub(super) at: (i32, i32),
    /// Font size, pixels: an even number (plotters places a glyph's rows from half the
    /// size, rounding an odd half inconsistently).
    pub(super) size: u32,
    pub(super) color: RGBColor,
    pub(super) align: HPos,
    /// Read upwards (a y-axis title) instead of left to right.
    pub(super) upwards: bool,
}

/// Draws text on one drawing area: on a bitmap glyph by glyph, each placed at its side
/// bearing ([`FontMetrics`]); in SVG as one text element the viewer lays out.
pub(super) struct Pen<'a, DB: DrawingBackend> {
    pub(super) area: &'a DrawingArea<DB, Shift>,
    pub(super) font: &'static FontMetrics,
    pub(super) bitmap: bool,
}

impl<DB: DrawingBackend> Pen<'_, DB> {
    pub(super) fn width(&self, text: &str, size: u32) -> i32 {
        self.font.width(text, size)
    }

    pub(super) fn draw(&self, label: &Label<'_>) -> anyhow::Result<()> {
        let metrics = self.font;
        let scale = metrics.scale(label.size);
        let (glyphs, width) = metrics.layout(label.text);
        let start = match label.align {
            HPos::Left => 0.0,
            HPos::Center => -width * scale / 2.0,
            HPos::Right => -width * scale,
        };
        if !self.bitmap {
            // SVG: a font size of plotters' is 1.24 em; make the em the bitmap's.
            let em = f64::from(metrics.units_per_em / metrics.height);
            let style = FontDesc::new(
                FontFamily::Name(FAMILY),
                f64::from(label.size) * 1.24 * em,
                FontStyle::Normal,
            )
            .transform(if label.upwards {
                FontTransform::Rotate270
            } else {
                FontTransform::None
            })
            .color(&label.color)
            .pos(Pos::new(label.align, VPos::Center));
            return self
                .area
                .draw_text(label.text, &style, label.at)
                .map_err(|e| anyhow!("drawing failed: {e:?}"));
        }
        // plotters draws a glyph's rows from half the font size above its baseline; the
        // baseline goes half an x-height below the anchor.
        let half = i32::try_from(label.size / 2).unwrap_or(0);
        let down = px(metrics.x_height * scale / 2.0 + 0.5) - half;
        let font = FontDesc::new(
            FontFamily::Name(FAMILY),
            f64::from(label.size),
            FontStyle::Normal,
        );
        let (anchor_x, anchor_y) = label.at;
        let mut buf = [0u8; 4];
        for (c, pen, bearing) in glyphs {
            // The outline's first pixel column is where ab_glyph puts it: its bearing
            // from the pen, rounded down.
            let left = px(start + pen * scale + 0.5) + px(bearing * scale);
            let drawn = font
                .draw(c.encode_utf8(&mut buf), (0, 0), |col, row, coverage| {
                    // Along the line and down from it, then turned for upward text.
                    let (along, across) = (left + col, row + down);
                    let at = if label.upwards {
                        (anchor_x + across, anchor_y - along)
                    } else {
                        (anchor_x + along, anchor_y + across)
                    };
                    if coverage <= 0.0 {
                        return Ok(());
                    }
                    let alpha = f64::from(coverage.min(1.0));
                    self.area.draw_pixel(at, &label.color.mix(alpha))
                })
                .map_err(|e| anyhow!("the embedded font: {e}"))?;
            drawn.map_err(|e| anyhow!("drawing failed: {e:?}"))?;
        }
        Ok(())
    }
}
