//! Plots of results and studies as SVG or PNG (chosen by the file extension),
//! drawn with `plotters`. Text uses a DejaVu Sans subset embedded in this crate
//! and rendered by `ab_glyph`, so no system font library is needed.

mod convergence;
mod series;
mod stability;

use std::path::Path;
use std::sync::Once;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::StudyError;

pub use convergence::ConvergencePlot;
pub use series::SeriesPlot;
pub use stability::StabilityPlot;

/// DejaVu Sans (Bitstream Vera licence, see assets/fonts/LICENSE-DejaVu.txt),
/// subset to Latin-1 and Greek.
static FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans-subset.ttf");

fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        for style in [FontStyle::Normal, FontStyle::Bold] {
            plotters::style::register_font("sans-serif", style, FONT)
                .unwrap_or_else(|_| panic!("the embedded font is a valid TrueType font"));
        }
    });
}

/// Something that can be drawn on any plotters backend.
pub trait Figure {
    /// Size in pixels (SVG user units).
    fn size(&self) -> (u32, u32);
    /// Draw on the whole area.
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String>;
}

/// Draw a figure into `path`: `.svg` or `.png`.
pub fn save(path: &Path, figure: &impl Figure) -> Result<(), StudyError> {
    register_font();
    let fail = |reason: String| StudyError::Plot {
        path: path.to_path_buf(),
        reason,
    };
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| fail(e.to_string()))?;
    }
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    match ext.as_deref() {
        Some("svg") => {
            let root = SVGBackend::new(path, figure.size()).into_drawing_area();
            root.fill(&WHITE).map_err(|e| fail(e.to_string()))?;
            figure.draw(&root).map_err(fail)?;
            root.present().map_err(|e| fail(e.to_string()))
        }
        Some("png") => {
            let root = BitMapBackend::new(path, figure.size()).into_drawing_area();
            root.fill(&WHITE).map_err(|e| fail(e.to_string()))?;
            figure.draw(&root).map_err(fail)?;
            root.present().map_err(|e| fail(e.to_string()))
        }
        _ => Err(fail("the file name must end in .svg or .png".into())),
    }
}

/// Line colours: the Tableau 10 palette, distinguishable and print-safe.
pub(crate) fn colour(i: usize) -> RGBColor {
    const PALETTE: [(u8, u8, u8); 10] = [
        (31, 119, 180),
        (255, 127, 14),
        (44, 160, 44),
        (214, 39, 40),
        (148, 103, 189),
        (140, 86, 75),
        (227, 119, 194),
        (127, 127, 127),
        (188, 189, 34),
        (23, 190, 207),
    ];
    let (r, g, b) = PALETTE[i % PALETTE.len()];
    RGBColor(r, g, b)
}

/// A finite range around `values`, padded by 5 %, never empty.
pub(crate) fn padded_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if !lo.is_finite() {
        return (-1.0, 1.0);
    }
    let span = hi - lo;
    if span <= 1e-300 + 1e-12 * lo.abs().max(hi.abs()) {
        let pad = lo.abs().max(1e-12) * 0.5;
        return (lo - pad, hi + pad);
    }
    (lo - 0.05 * span, hi + 0.05 * span)
}

/// Tick labels: plain for moderate magnitudes, scientific otherwise.
pub(crate) fn tick(v: &f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if (1e-2..1e4).contains(&a) {
        let s = format!("{v:.4}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        let s = format!("{v:.1e}");
        s.replace(".0e", "e")
    }
}

/// [`tick`] for an axis spanning `span`: a value within a billionth of the
/// span of zero (a tick placed at 0 with rounding error, `-5.6e-17`) is `0`.
pub(crate) fn tick_on(v: f64, span: f64) -> String {
    if v.abs() <= 1e-9 * span.abs() {
        "0".into()
    } else {
        tick(&v)
    }
}

/// Two significant digits: axis values of a log-spaced grid.
pub(crate) fn tick2(v: &f64) -> String {
    let a = v.abs();
    if a == 0.0 || !a.is_finite() {
        return format!("{v}");
    }
    let digits = a.log10().floor() as i32;
    let rounded = (v / 10f64.powi(digits - 1)).round() * 10f64.powi(digits - 1);
    if (-2..4).contains(&digits) {
        let decimals = (1 - digits).max(0) as usize;
        let s = format!("{rounded:.decimals$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    } else {
        format!("{rounded:.1e}").replace(".0e", "e")
    }
}

pub(crate) fn text_error<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

#[cfg(test)]
mod tests {
    use super::tick_on;

    #[test]
    fn a_tick_at_zero_with_rounding_error_reads_zero() {
        assert_eq!(tick_on(-5.551115123125783e-17, 2.0), "0");
        assert_eq!(tick_on(0.25, 2.0), "0.25");
        assert_eq!(tick_on(-3e-6, 1e-5), "-3.0e-6".replace(".0e", "e"));
    }
}
