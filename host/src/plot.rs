//! Line plots drawn with `plotters` (`SVGBackend`); the PNG is the same SVG rasterised by
//! `resvg`. Text uses DejaVu Sans embedded in the binary (the `dejavu` crate: `ab_glyph` lays it
//! out for plotters, resvg's font database holds it for the raster): no system fonts or
//! fontconfig are needed, and every character the report writes (lower case, µ, τ, Σ, −, ·) is
//! drawn as written.
//!
//! A [`Figure`] is a grid of [`Panel`]s (`columns` wide, filled row by row); each panel has its
//! own axis ranges (from the data; y padded by 5 %) and any number of [`Series`], with a legend
//! in its top right corner. A NaN point breaks a line (e.g. a measured ZMP that is not
//! available). Dash patterns are laid out in pixels along the whole polyline.

use plotters::coord::Shift;
use plotters::element::{Drawable, PointCollection};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters_backend::{BackendCoord, DrawingErrorKind};

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

/// A figure: panels in a grid.
#[derive(Clone, Debug, PartialEq)]
pub struct Figure {
    /// Figure title.
    pub title: String,
    /// Width, px.
    pub width: u32,
    /// Height of one row of panels including its margins, px.
    pub panel_height: u32,
    /// Panels per row (0 or 1: one column).
    pub columns: usize,
    /// The panels, row by row.
    pub panels: Vec<Panel>,
}

/// Height of the figure title band, px.
const TOP: u32 = 40;
/// The font family name the embedded font is registered under.
const FONT: &str = "sans-serif";

/// Registers the embedded DejaVu Sans once (plotters' `ab_glyph` font table).
fn register_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        if plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular()).is_err()
        {
            // The font ships inside the binary: this cannot fail short of a corrupted build.
            panic!("the embedded DejaVu Sans font does not parse");
        }
    });
}

/// Axis range and tick label precision.
#[derive(Clone, Debug, PartialEq)]
struct Axis {
    lo: f64,
    hi: f64,
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
        Axis { lo, hi, decimals }
    }
    fn label(&self, v: f64) -> String {
        // No "-0.000".
        let s = format!("{:.*}", self.decimals, v);
        if s.starts_with('-') && s[1..].chars().all(|c| c == '0' || c == '.') {
            s[1..].to_string()
        } else {
            s.replace('-', "−")
        }
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

/// A polyline in data coordinates, drawn with a dash pattern laid out in pixels.
struct DashedPath {
    points: Vec<(f64, f64)>,
    style: ShapeStyle,
    dash: Dash,
}

impl<'a> PointCollection<'a, (f64, f64)> for &'a DashedPath {
    type Point = &'a (f64, f64);
    type IntoIter = &'a [(f64, f64)];
    fn point_iter(self) -> &'a [(f64, f64)] {
        &self.points
    }
}

impl<DB: DrawingBackend> Drawable<DB> for DashedPath {
    fn draw<I: Iterator<Item = BackendCoord>>(
        &self,
        pos: I,
        backend: &mut DB,
        _: (u32, u32),
    ) -> Result<(), DrawingErrorKind<DB::ErrorType>> {
        let px: Vec<BackendCoord> = pos.collect();
        for piece in dash_pieces(&px, self.dash.pattern()) {
            backend.draw_path(piece, &self.style)?;
        }
        Ok(())
    }
}

/// A short legend sample of a line style (the legend's own element, at a pixel position).
struct LegendLine {
    at: BackendCoord,
    style: ShapeStyle,
    dash: Dash,
}

impl<'a> PointCollection<'a, BackendCoord> for &'a LegendLine {
    type Point = &'a BackendCoord;
    type IntoIter = std::iter::Once<&'a BackendCoord>;
    fn point_iter(self) -> Self::IntoIter {
        std::iter::once(&self.at)
    }
}

impl<DB: DrawingBackend> Drawable<DB> for LegendLine {
    fn draw<I: Iterator<Item = BackendCoord>>(
        &self,
        mut pos: I,
        backend: &mut DB,
        _: (u32, u32),
    ) -> Result<(), DrawingErrorKind<DB::ErrorType>> {
        if let Some((x, y)) = pos.next() {
            let line = [(x, y), (x + 30, y)];
            for piece in dash_pieces(&line, self.dash.pattern()) {
                backend.draw_path(piece, &self.style)?;
            }
        }
        Ok(())
    }
}

/// Splits a pixel polyline into its "on" pieces under a dash pattern (on, off, on, off, …
/// lengths in pixels; empty = solid), the pattern continuing across vertices.
fn dash_pieces(px: &[BackendCoord], pattern: &[f64]) -> Vec<Vec<BackendCoord>> {
    if pattern.is_empty() || px.len() < 2 {
        return if px.is_empty() {
            vec![]
        } else {
            vec![px.to_vec()]
        };
    }
    let mut out = Vec::new();
    let mut cur: Vec<BackendCoord> = Vec::new();
    let (mut idx, mut left, mut on) = (0usize, pattern[0], true);
    let round = |x: f64, y: f64| (x.round() as i32, y.round() as i32);
    for w in px.windows(2) {
        let (a, b) = (
            (f64::from(w[0].0), f64::from(w[0].1)),
            (f64::from(w[1].0), f64::from(w[1].1)),
        );
        let len = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt();
        let mut done = 0.0;
        if on && cur.is_empty() {
            cur.push(w[0]);
        }
        while len - done > left {
            done += left;
            let f = done / len;
            let p = round(a.0 + (b.0 - a.0) * f, a.1 + (b.1 - a.1) * f);
            if on {
                cur.push(p);
                out.push(std::mem::take(&mut cur));
            } else {
                cur = vec![p];
            }
            on = !on;
            idx = (idx + 1) % pattern.len();
            left = pattern[idx];
        }
        left -= len - done;
        if on {
            cur.push(w[1]);
        }
    }
    if on && cur.len() >= 2 {
        out.push(cur);
    }
    out
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
fn decimate(run: &[(f64, f64)], px: impl Fn(f64) -> i32) -> Vec<(f64, f64)> {
    let mut out: Vec<(f64, f64)> = Vec::with_capacity(run.len().min(4096));
    let mut i = 0;
    while i < run.len() {
        let col = px(run[i].0);
        let mut j = i;
        let (mut lo, mut hi) = (i, i);
        while j < run.len() && px(run[j].0) == col {
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

fn err(e: impl std::fmt::Display) -> String {
    format!("plot: {e}")
}

impl Figure {
    /// Rows of panels.
    fn rows(&self) -> usize {
        self.panels.len().max(1).div_ceil(self.columns.max(1))
    }

    /// Total height, px.
    pub fn height(&self) -> u32 {
        TOP + self.panel_height * self.rows() as u32
    }

    /// Draws the figure on any plotters drawing area of `width × height()` pixels.
    pub fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        register_font();
        root.fill(&WHITE).map_err(err)?;
        let (head, body) = root.split_vertically(TOP);
        head.draw(&Text::new(
            self.title.clone(),
            (self.width as i32 / 2, TOP as i32 / 2),
            TextStyle::from((FONT, 20).into_font())
                .pos(Pos::new(HPos::Center, VPos::Center))
                .color(&BLACK),
        ))
        .map_err(err)?;
        let cells = body.split_evenly((self.rows(), self.columns.max(1)));
        for (p, area) in self.panels.iter().zip(cells) {
            draw_panel(p, &area)?;
        }
        root.present().map_err(err)
    }

    /// The figure as an SVG document.
    pub fn to_svg(&self) -> Result<String, String> {
        let mut s = String::new();
        {
            let root =
                SVGBackend::with_string(&mut s, (self.width, self.height())).into_drawing_area();
            self.draw(&root)?;
        }
        Ok(s)
    }

    /// The figure rasterised: its SVG rendered by resvg with the embedded font.
    pub fn to_pixmap(&self) -> Result<resvg::tiny_skia::Pixmap, String> {
        let svg = self.to_svg()?;
        let mut opt = resvg::usvg::Options {
            font_family: "DejaVu Sans".into(),
            ..Default::default()
        };
        let db = opt.fontdb_mut();
        db.load_font_data(dejavu::sans::regular().to_vec());
        db.set_sans_serif_family("DejaVu Sans");
        let tree = resvg::usvg::Tree::from_str(&svg, &opt).map_err(err)?;
        let mut pixmap = resvg::tiny_skia::Pixmap::new(self.width, self.height())
            .ok_or_else(|| format!("plot: bad size {}×{}", self.width, self.height()))?;
        pixmap.fill(resvg::tiny_skia::Color::WHITE);
        resvg::render(
            &tree,
            resvg::tiny_skia::Transform::default(),
            &mut pixmap.as_mut(),
        );
        Ok(pixmap)
    }

    /// The figure rasterised as a PNG file.
    pub fn to_png(&self) -> Result<Vec<u8>, String> {
        self.to_pixmap()?.encode_png().map_err(err)
    }
}

fn draw_panel<DB: DrawingBackend>(p: &Panel, area: &DrawingArea<DB, Shift>) -> Result<(), String> {
    let ((xl, xh), (yl, yh)) = data_range(p);
    let (xa, ya) = (Axis::new(xl, xh, false), Axis::new(yl, yh, true));
    let mut chart = ChartBuilder::on(area)
        .caption(&p.title, (FONT, 16))
        .margin_left(10)
        .margin_right(20)
        .margin_top(4)
        .margin_bottom(6)
        .x_label_area_size(44)
        .y_label_area_size(78)
        .build_cartesian_2d(xa.lo..xa.hi, ya.lo..ya.hi)
        .map_err(err)?;
    let (fx, fy) = (|v: &f64| xa.label(*v), |v: &f64| ya.label(*v));
    chart
        .configure_mesh()
        .x_labels(12)
        .y_labels(8)
        .max_light_lines(1)
        .light_line_style(RGBColor(240, 240, 240))
        .bold_line_style(RGBColor(215, 215, 215))
        .x_label_formatter(&fx)
        .y_label_formatter(&fy)
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 14))
        .x_desc(p.x_label.as_str())
        .y_desc(p.y_label.as_str())
        .draw()
        .map_err(err)?;
    let mut labelled = false;
    for ser in &p.series {
        let style = ShapeStyle {
            color: RGBColor(ser.color[0], ser.color[1], ser.color[2]).to_rgba(),
            filled: false,
            stroke_width: ser.width.round().max(1.0) as u32,
        };
        let paths: Vec<DashedPath> = runs(&ser.points)
            .into_iter()
            .map(|run| DashedPath {
                points: decimate(run, |x| chart.backend_coord(&(x, 0.0)).0),
                style,
                dash: ser.dash,
            })
            .collect();
        let anno = chart.draw_series(paths).map_err(err)?;
        if !ser.label.is_empty() {
            let dash = ser.dash;
            anno.label(ser.label.as_str())
                .legend(move |(x, y)| LegendLine {
                    at: (x - 2, y),
                    style,
                    dash,
                });
            labelled = true;
        }
    }
    if labelled {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .legend_area_size(36)
            .label_font((FONT, 13))
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(150, 150, 150))
            .draw()
            .map_err(err)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nice_axis() {
        let a = Axis::new(0.0, 1.0, false);
        assert_eq!((a.lo, a.hi, a.decimals), (0.0, 1.0, 1));
        let a = Axis::new(0.1, 0.1, true);
        assert!(a.hi > a.lo);
        assert_eq!(Axis::new(-0.05, 0.05, false).label(-0.0001), "0.00");
        assert_eq!(Axis::new(-0.05, 0.05, false).label(-0.02), "−0.02");
    }

    #[test]
    fn dashes_follow_the_pattern_across_vertices() {
        // 30 px right then 30 px down, dashes of 8 on / 5 off.
        let pieces = dash_pieces(&[(0, 0), (30, 0), (30, 30)], &[8.0, 5.0]);
        let len = |p: &Vec<BackendCoord>| -> f64 {
            p.windows(2)
                .map(|w| f64::from((w[1].0 - w[0].0).abs() + (w[1].1 - w[0].1).abs()))
                .sum()
        };
        let lens: Vec<f64> = pieces.iter().map(len).collect();
        // 60 px = 4 × 13 + 8: five dashes, the third bending round the corner.
        assert_eq!(lens, vec![8.0, 8.0, 8.0, 8.0, 8.0], "{pieces:?}");
        assert_eq!(pieces[2], vec![(26, 0), (30, 0), (30, 4)]);
        assert_eq!(dash_pieces(&[(0, 0), (5, 5)], &[]).len(), 1);
    }

    fn figure() -> Figure {
        Figure {
            title: "ZMP x — reference (m) vs µ, τ·s".into(),
            width: 400,
            panel_height: 240,
            columns: 1,
            panels: vec![Panel {
                title: "p".into(),
                x_label: "t (s)".into(),
                y_label: "y (mm)".into(),
                series: vec![Series {
                    label: "a<b".into(),
                    color: [255, 0, 0],
                    dash: Dash::Solid,
                    width: 2.0,
                    points: vec![
                        (0.0, 0.0),
                        (1.0, 1.0),
                        (f64::NAN, 0.0),
                        (2.0, 0.0),
                        (3.0, 1.0),
                    ],
                }],
            }],
        }
    }

    #[test]
    fn png_and_svg() {
        let fig = figure();
        let svg = fig.to_svg().unwrap();
        assert!(svg.starts_with("<svg"), "{svg}");
        assert!(svg.contains("a&lt;b") && svg.contains("µ") && svg.contains("t (s)"));
        // Two runs (the NaN breaks the line) plus the legend sample.
        assert!(svg.matches("stroke=\"#FF0000\"").count() >= 3, "{svg}");
        let png = fig.to_png().unwrap();
        assert_eq!(&png[1..4], b"PNG");
        let img = fig.to_pixmap().unwrap();
        assert_eq!((img.width(), img.height()), (400, 280));
        // Red line pixels and dark text pixels are drawn.
        let px = |p: &resvg::tiny_skia::PremultipliedColorU8| [p.red(), p.green(), p.blue()];
        let red = img.pixels().iter().filter(|p| px(p) == [255, 0, 0]).count();
        let dark = img
            .pixels()
            .iter()
            .filter(|p| px(p).iter().all(|&c| c < 80))
            .count();
        assert!(red > 100 && dark > 500, "red {red}, dark {dark}");
    }
}
