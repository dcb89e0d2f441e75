//! Minimal line plots: hand-written SVG and PNG (a small rasteriser with a built-in 5×7 font:
//! digits, capital letters — lower case is drawn in capitals — and common punctuation; the
//! y-axis label sits above the axis instead of being rotated).
//!
//! A [`Figure`] is a column of [`Panel`]s sharing nothing but the width; each panel has its own
//! axis ranges (from the data, padded by 5 %) and any number of [`Series`]. A NaN point breaks a
//! line (e.g. a measured ZMP that is not available).

use std::fmt::Write as _;

/// Line style.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dash {
    /// Solid line.
    Solid,
    /// Dashed line.
    Dashed,
    /// Dash-dot line.
    DashDot,
    /// Dotted line.
    Dotted,
}

impl Dash {
    /// On/off lengths in pixels (empty = solid).
    fn pattern(self) -> &'static [f64] {
        match self {
            Dash::Solid => &[],
            Dash::Dashed => &[8.0, 5.0],
            Dash::DashDot => &[10.0, 4.0, 2.0, 4.0],
            Dash::Dotted => &[2.0, 3.0],
        }
    }
}

/// One line of a panel.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    /// Legend text (empty: not in the legend).
    pub label: String,
    /// RGB colour.
    pub color: [u8; 3],
    /// Line style.
    pub dash: Dash,
    /// Line width, px.
    pub width: f64,
    /// Points (x, y); NaN breaks the line.
    pub points: Vec<(f64, f64)>,
}

/// One plot area.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Panel {
    /// Title above the panel.
    pub title: String,
    /// x axis label.
    pub x_label: String,
    /// y axis label.
    pub y_label: String,
    /// The lines.
    pub series: Vec<Series>,
}

/// A figure: panels stacked vertically.
#[derive(Clone, Debug, PartialEq)]
pub struct Figure {
    /// Figure title.
    pub title: String,
    /// Width, px.
    pub width: u32,
    /// Height of one panel including its margins, px.
    pub panel_height: u32,
    /// The panels, top to bottom.
    pub panels: Vec<Panel>,
}

const LEFT: f64 = 90.0;
const RIGHT: f64 = 20.0;
const TOP: f64 = 40.0;
const PANEL_TOP: f64 = 28.0;
const PANEL_BOTTOM: f64 = 48.0;

/// Axis range and ticks.
#[derive(Clone, Debug, PartialEq)]
struct Axis {
    lo: f64,
    hi: f64,
    ticks: Vec<f64>,
    decimals: usize,
}

fn nice_step(span: f64, target: f64) -> f64 {
    let raw = span / target;
    let mag = 10f64.powf(raw.log10().floor());
    let f = raw / mag;
    let n = if f <= 1.0 {
        1.0
    } else if f <= 2.0 {
        2.0
    } else if f <= 5.0 {
        5.0
    } else {
        10.0
    };
    n * mag
}

impl Axis {
    fn new(lo: f64, hi: f64, pad: bool) -> Axis {
        let (mut lo, mut hi) = if lo.is_finite() && hi.is_finite() && hi >= lo {
            (lo, hi)
        } else {
            (0.0, 1.0)
        };
        if hi - lo < 1e-12 {
            let c = lo;
            let h = if c.abs() > 1e-9 { c.abs() * 0.1 } else { 1e-3 };
            lo = c - h;
            hi = c + h;
        } else if pad {
            let p = (hi - lo) * 0.05;
            lo -= p;
            hi += p;
        }
        let step = nice_step(hi - lo, 8.0);
        let decimals = if step >= 1.0 {
            0
        } else {
            (-step.log10().floor()) as usize
        };
        let mut ticks = Vec::new();
        let mut v = (lo / step).ceil() * step;
        while v <= hi + step * 1e-9 && ticks.len() < 50 {
            ticks.push(if v.abs() < step * 1e-9 { 0.0 } else { v });
            v += step;
        }
        Axis {
            lo,
            hi,
            ticks,
            decimals,
        }
    }
    fn label(&self, v: f64) -> String {
        format!("{:.*}", self.decimals, v)
    }
}

/// Pixel geometry of one panel.
struct Frame {
    x0: f64,
    y0: f64,
    w: f64,
    h: f64,
    xa: Axis,
    ya: Axis,
}

impl Frame {
    fn px(&self, x: f64) -> f64 {
        self.x0 + (x - self.xa.lo) / (self.xa.hi - self.xa.lo) * self.w
    }
    fn py(&self, y: f64) -> f64 {
        self.y0 + self.h - (y - self.ya.lo) / (self.ya.hi - self.ya.lo) * self.h
    }
}

fn data_range(panel: &Panel) -> ((f64, f64), (f64, f64)) {
    let (mut xl, mut xh, mut yl, mut yh) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for s in &panel.series {
        for &(x, y) in &s.points {
            if x.is_finite() && y.is_finite() {
                xl = xl.min(x);
                xh = xh.max(x);
                yl = yl.min(y);
                yh = yh.max(y);
            }
        }
    }
    ((xl, xh), (yl, yh))
}

impl Figure {
    /// Total height, px.
    pub fn height(&self) -> u32 {
        TOP as u32 + self.panel_height * self.panels.len().max(1) as u32
    }

    fn frames(&self) -> Vec<Frame> {
        self.panels
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let ((xl, xh), (yl, yh)) = data_range(p);
                let top = TOP + i as f64 * f64::from(self.panel_height) + PANEL_TOP;
                Frame {
                    x0: LEFT,
                    y0: top,
                    w: f64::from(self.width) - LEFT - RIGHT,
                    h: f64::from(self.panel_height) - PANEL_TOP - PANEL_BOTTOM,
                    xa: Axis::new(xl, xh, false),
                    ya: Axis::new(yl, yh, true),
                }
            })
            .collect()
    }

    /// The figure as an SVG document.
    pub fn to_svg(&self) -> String {
        let (w, h) = (self.width, self.height());
        let mut s = String::new();
        let _ = writeln!(
            s,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="sans-serif" font-size="12">"#
        );
        let _ = writeln!(
            s,
            r#"<rect x="0" y="0" width="{w}" height="{h}" fill="white"/>"#
        );
        let _ = writeln!(
            s,
            r#"<text x="{}" y="24" text-anchor="middle" font-size="16">{}</text>"#,
            w / 2,
            esc(&self.title)
        );
        for (i, (p, f)) in self.panels.iter().zip(self.frames()).enumerate() {
            let _ = writeln!(
                s,
                r#"<clipPath id="clip{i}"><rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}"/></clipPath>"#,
                f.x0, f.y0, f.w, f.h
            );
            // Grid and tick labels.
            for &t in &f.xa.ticks {
                let x = f.px(t);
                let _ = writeln!(
                    s,
                    r##"<line x1="{x:.1}" y1="{:.1}" x2="{x:.1}" y2="{:.1}" stroke="#e0e0e0"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
                    f.y0,
                    f.y0 + f.h,
                    f.y0 + f.h + 16.0,
                    f.xa.label(t)
                );
            }
            for &t in &f.ya.ticks {
                let y = f.py(t);
                let _ = writeln!(
                    s,
                    r##"<line x1="{:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#e0e0e0"/><text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"##,
                    f.x0,
                    f.x0 + f.w,
                    f.x0 - 6.0,
                    y + 4.0,
                    f.ya.label(t)
                );
            }
            let _ = writeln!(
                s,
                r#"<rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="none" stroke="black"/>"#,
                f.x0, f.y0, f.w, f.h
            );
            let _ = writeln!(
                s,
                r#"<text x="{:.1}" y="{:.1}" text-anchor="middle" font-size="14">{}</text>"#,
                f.x0 + f.w / 2.0,
                f.y0 - 8.0,
                esc(&p.title)
            );
            let _ = writeln!(
                s,
                r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
                f.x0 + f.w / 2.0,
                f.y0 + f.h + 36.0,
                esc(&p.x_label)
            );
            let (lx, ly) = (18.0, f.y0 + f.h / 2.0);
            let _ = writeln!(
                s,
                r#"<text x="{lx}" y="{ly:.1}" text-anchor="middle" transform="rotate(-90 {lx} {ly:.1})">{}</text>"#,
                esc(&p.y_label)
            );
            // Lines.
            for ser in &p.series {
                let dash_attr = dash_attr(ser);
                let color = hex(ser.color);
                for run in runs(&ser.points) {
                    let run = decimate(run, |x| f.px(x));
                    let mut d = String::new();
                    let mut last = (f64::NAN, f64::NAN);
                    for (k, &(x, y)) in run.iter().enumerate() {
                        let (px, py) = (
                            (f.px(x) * 10.0).round() / 10.0,
                            (f.py(y) * 10.0).round() / 10.0,
                        );
                        if (px, py) == last && k + 1 != run.len() {
                            continue;
                        }
                        last = (px, py);
                        let _ = write!(
                            d,
                            "{}{px:.1},{py:.1}",
                            if d.is_empty() { "M" } else { " L" }
                        );
                    }
                    let _ = writeln!(
                        s,
                        r#"<path d="{d}" fill="none" stroke="{color}" stroke-width="{}"{dash_attr} clip-path="url(#clip{i})"/>"#,
                        ser.width
                    );
                }
            }
            // Legend (top right inside the frame).
            let lw = 200.0;
            let legend: Vec<&Series> = p.series.iter().filter(|s| !s.label.is_empty()).collect();
            let lh = 16.0 * legend.len() as f64 + 6.0;
            let (lx0, ly0) = (f.x0 + f.w - lw - 6.0, f.y0 + 6.0);
            if !legend.is_empty() {
                let _ = writeln!(
                    s,
                    r##"<rect x="{lx0:.1}" y="{ly0:.1}" width="{lw}" height="{lh}" fill="white" fill-opacity="0.85" stroke="#999"/>"##
                );
            }
            for (k, ser) in legend.iter().enumerate() {
                let y = ly0 + 14.0 + 16.0 * k as f64;
                let dash_attr = dash_attr(ser);
                let _ = writeln!(
                    s,
                    r#"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="{}" stroke-width="{}"{dash_attr}/><text x="{:.1}" y="{:.1}">{}</text>"#,
                    lx0 + 6.0,
                    y - 4.0,
                    lx0 + 40.0,
                    y - 4.0,
                    hex(ser.color),
                    ser.width,
                    lx0 + 46.0,
                    y,
                    esc(&ser.label)
                );
            }
        }
        s.push_str("</svg>\n");
        s
    }

    /// The figure rasterised as a PNG file.
    pub fn to_png(&self) -> Vec<u8> {
        let mut c = Canvas::new(self.width, self.height());
        for (p, f) in self.panels.iter().zip(self.frames()) {
            let clip = (f.x0, f.y0, f.x0 + f.w, f.y0 + f.h);
            let full = (0.0, 0.0, f64::from(c.w), f64::from(c.h));
            let grid = [224, 224, 224];
            for &t in &f.xa.ticks {
                let x = f.px(t);
                c.polyline(&[(x, f.y0), (x, f.y0 + f.h)], grid, 1.0, Dash::Solid, full);
                let label = f.xa.label(t);
                let tw = text_width(&label, 2);
                c.text(&label, (x - tw / 2.0) as i64, (f.y0 + f.h + 6.0) as i64, 2);
            }
            for &t in &f.ya.ticks {
                let y = f.py(t);
                c.polyline(&[(f.x0, y), (f.x0 + f.w, y)], grid, 1.0, Dash::Solid, full);
                let label = f.ya.label(t);
                let tw = text_width(&label, 2);
                c.text(&label, (f.x0 - 6.0 - tw) as i64, (y - 7.0) as i64, 2);
            }
            let frame = [
                (f.x0, f.y0),
                (f.x0 + f.w, f.y0),
                (f.x0 + f.w, f.y0 + f.h),
                (f.x0, f.y0 + f.h),
                (f.x0, f.y0),
            ];
            c.polyline(&frame, [0, 0, 0], 1.0, Dash::Solid, full);
            for ser in &p.series {
                for run in runs(&ser.points) {
                    let pts: Vec<(f64, f64)> = decimate(run, |x| f.px(x))
                        .iter()
                        .map(|&(x, y)| (f.px(x), f.py(y)))
                        .collect();
                    c.polyline(&pts, ser.color, ser.width, ser.dash, clip);
                }
            }
            // Panel title above the frame, axis labels, legend box (top right, as in the SVG).
            let tw = text_width(&p.title, 2);
            c.text(
                &p.title,
                (f.x0 + (f.w - tw) / 2.0) as i64,
                (f.y0 - 22.0) as i64,
                2,
            );
            let tw = text_width(&p.x_label, 2);
            c.text(
                &p.x_label,
                (f.x0 + (f.w - tw) / 2.0) as i64,
                (f.y0 + f.h + 28.0) as i64,
                2,
            );
            c.text(&p.y_label, 4, (f.y0 - 12.0) as i64, 1);
            let legend: Vec<&Series> = p.series.iter().filter(|s| !s.label.is_empty()).collect();
            if !legend.is_empty() {
                let longest = legend
                    .iter()
                    .map(|s| text_width(&s.label, 1))
                    .fold(0.0, f64::max);
                let (lw, lh) = (longest + 54.0, 12.0 * legend.len() as f64 + 6.0);
                let (lx0, ly0) = (f.x0 + f.w - lw - 6.0, f.y0 + 6.0);
                c.fill_rect(lx0, ly0, lw, lh, [255, 255, 255]);
                let border = [
                    (lx0, ly0),
                    (lx0 + lw, ly0),
                    (lx0 + lw, ly0 + lh),
                    (lx0, ly0 + lh),
                    (lx0, ly0),
                ];
                c.polyline(&border, [153, 153, 153], 1.0, Dash::Solid, full);
                for (k, ser) in legend.iter().enumerate() {
                    let y = ly0 + 9.0 + 12.0 * k as f64;
                    c.polyline(
                        &[(lx0 + 6.0, y), (lx0 + 40.0, y)],
                        ser.color,
                        ser.width,
                        ser.dash,
                        full,
                    );
                    c.text(&ser.label, (lx0 + 46.0) as i64, (y - 3.0) as i64, 1);
                }
            }
        }
        let tw = text_width(&self.title, 2);
        c.text(
            &self.title,
            ((f64::from(self.width) - tw) / 2.0) as i64,
            12,
            2,
        );
        c.encode_png()
    }
}

/// Splits points into runs of finite points (NaN breaks a line).
fn runs(points: &[(f64, f64)]) -> Vec<&[(f64, f64)]> {
    let mut out = Vec::new();
    let mut start = None;
    for (i, &(x, y)) in points.iter().enumerate() {
        let ok = x.is_finite() && y.is_finite();
        match (ok, start) {
            (true, None) => start = Some(i),
            (false, Some(s)) => {
                out.push(&points[s..i]);
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        out.push(&points[s..]);
    }
    out
}

/// Keeps at most first, min, max and last of the points in each pixel column (`px` maps x to
/// pixels): the drawn shape is unchanged, the SVG stays small.
fn decimate(run: &[(f64, f64)], px: impl Fn(f64) -> f64) -> Vec<(f64, f64)> {
    let mut out: Vec<(f64, f64)> = Vec::with_capacity(run.len().min(4096));
    let mut i = 0;
    while i < run.len() {
        let col = px(run[i].0).floor();
        let mut j = i;
        let (mut lo, mut hi) = (i, i);
        while j < run.len() && px(run[j].0).floor() == col {
            if run[j].1 < run[lo].1 {
                lo = j;
            }
            if run[j].1 > run[hi].1 {
                hi = j;
            }
            j += 1;
        }
        let mut keep = [i, lo, hi, j - 1];
        keep.sort_unstable();
        let mut last = usize::MAX;
        for k in keep {
            if k != last {
                out.push(run[k]);
                last = k;
            }
        }
        i = j;
    }
    out
}

fn hex(c: [u8; 3]) -> String {
    format!("#{:02x}{:02x}{:02x}", c[0], c[1], c[2])
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// An RGB raster.
pub struct Canvas {
    w: u32,
    h: u32,
    px: Vec<u8>,
}

impl Canvas {
    /// A white canvas.
    pub fn new(w: u32, h: u32) -> Canvas {
        Canvas {
            w,
            h,
            px: vec![255; w as usize * h as usize * 3],
        }
    }

    /// The colour at (x, y) (white outside).
    pub fn get(&self, x: u32, y: u32) -> [u8; 3] {
        if x >= self.w || y >= self.h {
            return [255; 3];
        }
        let i = (y as usize * self.w as usize + x as usize) * 3;
        [self.px[i], self.px[i + 1], self.px[i + 2]]
    }

    fn set(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x < 0 || y < 0 || x >= i64::from(self.w) || y >= i64::from(self.h) {
            return;
        }
        let i = (y as usize * self.w as usize + x as usize) * 3;
        self.px[i..i + 3].copy_from_slice(&c);
    }

    fn stamp(&mut self, x: f64, y: f64, r: f64, c: [u8; 3], clip: (f64, f64, f64, f64)) {
        if x < clip.0 - 0.5 || x > clip.2 + 0.5 || y < clip.1 - 0.5 || y > clip.3 + 0.5 {
            return;
        }
        let r = r.max(0.5);
        let (x0, x1) = ((x - r + 0.5).floor() as i64, (x + r - 0.5).ceil() as i64);
        let (y0, y1) = ((y - r + 0.5).floor() as i64, (y + r - 0.5).ceil() as i64);
        for yy in y0..=y1.max(y0) {
            for xx in x0..=x1.max(x0) {
                self.set(xx, yy, c);
            }
        }
    }

    /// Draws a polyline with a dash pattern continuing across vertices.
    pub fn polyline(
        &mut self,
        pts: &[(f64, f64)],
        c: [u8; 3],
        width: f64,
        dash: Dash,
        clip: (f64, f64, f64, f64),
    ) {
        let pat = dash.pattern();
        let period: f64 = pat.iter().sum();
        let mut dist = 0.0f64;
        let r = width / 2.0;
        if pts.len() == 1 {
            self.stamp(pts[0].0, pts[0].1, r, c, clip);
        }
        for w in pts.windows(2) {
            let (a, b) = (w[0], w[1]);
            let len = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt();
            if !len.is_finite() || len > 1e5 {
                continue;
            }
            let n = (len / 0.5).ceil().max(1.0) as usize;
            for k in 0..=n {
                let f = k as f64 / n as f64;
                let on = if period > 0.0 {
                    let mut m = (dist + f * len) % period;
                    let mut on = true;
                    let mut idx = 0;
                    while m >= pat[idx] {
                        m -= pat[idx];
                        idx = (idx + 1) % pat.len();
                        on = !on;
                    }
                    on
                } else {
                    true
                };
                if on {
                    self.stamp(a.0 + (b.0 - a.0) * f, a.1 + (b.1 - a.1) * f, r, c, clip);
                }
            }
            dist += len;
        }
    }

    /// Fills a rectangle (clipped to the canvas).
    pub fn fill_rect(&mut self, x: f64, y: f64, w: f64, h: f64, c: [u8; 3]) {
        let (x0, y0) = (x.round() as i64, y.round() as i64);
        let (x1, y1) = ((x + w).round() as i64, (y + h).round() as i64);
        for yy in y0..y1 {
            for xx in x0..x1 {
                self.set(xx, yy, c);
            }
        }
    }

    /// Draws text in the built-in 5×7 font (digits, capitals, punctuation; others are blanks).
    pub fn text(&mut self, s: &str, x: i64, y: i64, scale: i64) {
        let mut cx = x;
        for ch in s.chars() {
            if let Some(g) = glyph(ch) {
                for (row, bits) in g.iter().enumerate() {
                    for col in 0..5 {
                        if bits & (0x10 >> col) != 0 {
                            for dy in 0..scale {
                                for dx in 0..scale {
                                    self.set(
                                        cx + col * scale + dx,
                                        y + row as i64 * scale + dy,
                                        [0, 0, 0],
                                    );
                                }
                            }
                        }
                    }
                }
            }
            cx += 6 * scale;
        }
    }

    /// Encodes the canvas as an RGB PNG (zlib via miniz_oxide).
    pub fn encode_png(&self) -> Vec<u8> {
        let stride = self.w as usize * 3;
        let mut raw = Vec::with_capacity((stride + 1) * self.h as usize);
        for row in self.px.chunks(stride.max(1)) {
            raw.push(0); // filter: none
            raw.extend_from_slice(row);
        }
        let z = miniz_oxide::deflate::compress_to_vec_zlib(&raw, 6);
        let mut out = vec![0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A];
        let mut ihdr = Vec::with_capacity(13);
        ihdr.extend_from_slice(&self.w.to_be_bytes());
        ihdr.extend_from_slice(&self.h.to_be_bytes());
        ihdr.extend_from_slice(&[8, 2, 0, 0, 0]); // 8-bit RGB, deflate, no filter set, no interlace
        chunk(&mut out, b"IHDR", &ihdr);
        chunk(&mut out, b"IDAT", &z);
        chunk(&mut out, b"IEND", &[]);
        out
    }
}

fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend_from_slice(&(data.len() as u32).to_be_bytes());
    let start = out.len();
    out.extend_from_slice(kind);
    out.extend_from_slice(data);
    let crc = crc32(&out[start..]);
    out.extend_from_slice(&crc.to_be_bytes());
}

/// CRC-32 (ISO-HDLC, as PNG uses).
pub fn crc32(data: &[u8]) -> u32 {
    let mut c = 0xFFFF_FFFFu32;
    for &b in data {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
        }
    }
    !c
}

fn text_width(s: &str, scale: i64) -> f64 {
    (s.chars().count() as i64 * 6 * scale - scale) as f64
}

/// 5×7 glyphs (rows top to bottom, bit 4 = leftmost column): digits, capitals (lower case maps
/// to them), space and common punctuation; `None` for anything else.
fn glyph(c: char) -> Option<[u8; 7]> {
    let c = match c {
        '−' => '-',
        '×' => 'X',
        'µ' | 'μ' => 'U',
        c => c.to_ascii_uppercase(),
    };
    Some(match c {
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        'A' => [0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'B' => [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E],
        'C' => [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E],
        'D' => [0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C],
        'E' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F],
        'F' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10],
        'G' => [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F],
        'H' => [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'I' => [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'J' => [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C],
        'K' => [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11],
        'L' => [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F],
        'M' => [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11],
        'N' => [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11],
        'O' => [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'P' => [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10],
        'Q' => [0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D],
        'R' => [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11],
        'S' => [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E],
        'T' => [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        'U' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'V' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'W' => [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A],
        'X' => [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11],
        'Y' => [0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04],
        'Z' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F],
        ' ' => [0x00; 7],
        '-' => [0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00],
        '.' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C],
        ',' => [0x00, 0x00, 0x00, 0x00, 0x0C, 0x04, 0x08],
        ':' => [0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        '[' => [0x0E, 0x08, 0x08, 0x08, 0x08, 0x08, 0x0E],
        ']' => [0x0E, 0x02, 0x02, 0x02, 0x02, 0x02, 0x0E],
        '/' => [0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00],
        '%' => [0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03],
        '+' => [0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00],
        '=' => [0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00],
        '_' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1F],
        '<' => [0x02, 0x04, 0x08, 0x10, 0x08, 0x04, 0x02],
        '>' => [0x08, 0x04, 0x02, 0x01, 0x02, 0x04, 0x08],
        '|' => [0x04; 7],
        '\'' => [0x04, 0x04, 0x08, 0x00, 0x00, 0x00, 0x00],
        _ => return None,
    })
}

/// The SVG `stroke-dasharray` attribute of a series ("" for a solid line).
fn dash_attr(ser: &Series) -> String {
    let dash = ser.dash.pattern();
    if dash.is_empty() {
        return String::new();
    }
    let parts: Vec<String> = dash.iter().map(|d| format!("{d}")).collect();
    format!(r#" stroke-dasharray="{}""#, parts.join(" "))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32_check_value() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn nice_axis() {
        let a = Axis::new(0.0, 1.0, false);
        assert_eq!(a.ticks.first(), Some(&0.0));
        assert!(a.ticks.len() >= 4 && a.ticks.len() <= 12);
        let a = Axis::new(0.1, 0.1, true);
        assert!(a.hi > a.lo);
    }

    #[test]
    fn font_covers_letters_digits_and_labels_distinctly() {
        let chars: Vec<char> = ('0'..='9').chain('A'..='Z').collect();
        let glyphs: Vec<[u8; 7]> = chars.iter().map(|&c| glyph(c).unwrap()).collect();
        for i in 0..glyphs.len() {
            assert!(glyphs[i].iter().all(|r| *r < 0x20), "{}", chars[i]);
            for j in i + 1..glyphs.len() {
                // Every glyph is its own (O and 0 too).
                assert_ne!(glyphs[i], glyphs[j], "{} and {}", chars[i], chars[j]);
            }
        }
        assert_eq!(glyph('a'), glyph('A'));
        assert_eq!(glyph('−'), glyph('-'));
        for c in "ZMP reference vs response (tlipfm), t (s) / 5 % [m]: x_y".chars() {
            assert!(glyph(c).is_some(), "no glyph for {c:?}");
        }
    }

    #[test]
    fn text_draws_the_glyph_bits() {
        let mut c = Canvas::new(20, 10);
        c.text("T", 1, 2, 1);
        let g = glyph('T').unwrap();
        for (row, bits) in g.iter().enumerate() {
            for col in 0..5u32 {
                let ink = c.get(1 + col, 2 + row as u32) == [0, 0, 0];
                assert_eq!(ink, bits & (0x10 >> col) != 0, "row {row} col {col}");
            }
        }
    }

    #[test]
    fn png_and_svg() {
        let fig = Figure {
            title: "t".into(),
            width: 200,
            panel_height: 120,
            panels: vec![Panel {
                title: "p".into(),
                x_label: "x".into(),
                y_label: "y".into(),
                series: vec![Series {
                    label: "a<b".into(),
                    color: [255, 0, 0],
                    dash: Dash::DashDot,
                    width: 1.5,
                    points: vec![
                        (0.0, 0.0),
                        (1.0, 1.0),
                        (f64::NAN, 0.0),
                        (2.0, 0.0),
                        (3.0, 1.0),
                    ],
                }],
            }],
        };
        let svg = fig.to_svg();
        assert!(
            svg.starts_with("<svg") && svg.contains("a&lt;b") && svg.matches("<path").count() == 2
        );
        let png = fig.to_png();
        assert_eq!(&png[1..4], b"PNG");
        assert_eq!(&png[12..16], b"IHDR");
    }
}
