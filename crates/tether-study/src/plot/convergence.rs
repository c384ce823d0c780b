//! Error over H on log-log axes, with reference slopes.

use plotters::coord::Shift;
use plotters::prelude::*;

use super::{colour, text_error, tick, Figure};
use crate::ConvergenceCurve;

/// Convergence curves of several variants.
pub struct ConvergencePlot<'a> {
    /// Figure title.
    pub title: String,
    /// What the error measures (y-axis title).
    pub error_label: String,
    /// The x-axis title: the macro-step size H, or the work it took.
    pub x_label: String,
    /// The curves.
    pub curves: &'a [ConvergenceCurve],
    /// Orders of the dashed reference slopes (e.g. `[1, 2]`).
    pub slopes: Vec<u32>,
}

impl Figure for ConvergencePlot<'_> {
    fn size(&self) -> (u32, u32) {
        (900, 680)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let points: Vec<(f64, f64)> = self
            .curves
            .iter()
            .flat_map(|c| c.points.iter())
            .filter(|p| p.error.is_finite() && p.error > 0.0)
            .map(|p| (p.step, p.error))
            .collect();
        let all_h: Vec<f64> = self
            .curves
            .iter()
            .flat_map(|c| c.points.iter().map(|p| p.step))
            .collect();
        let (h0, h1) = all_h
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(a, b), &h| (a.min(h), b.max(h)));
        let (e0, e1) = points
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(a, b), &(_, e)| {
                (a.min(e), b.max(e))
            });
        let (e0, e1) = if points.is_empty() {
            (1e-3, 1.0)
        } else {
            (e0 / 3.0, e1 * 3.0)
        };
        let mut chart = ChartBuilder::on(root)
            .caption(&self.title, ("sans-serif", 24))
            .margin(14)
            .x_label_area_size(48)
            .y_label_area_size(90)
            .build_cartesian_2d((h0 / 1.3..h1 * 1.3).log_scale(), (e0..e1).log_scale())
            .map_err(text_error)?;
        chart
            .configure_mesh()
            .x_desc(self.x_label.as_str())
            .y_desc(self.error_label.as_str())
            .x_label_formatter(&tick)
            .y_label_formatter(&tick)
            .label_style(("sans-serif", 16))
            .axis_desc_style(("sans-serif", 18))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()
            .map_err(text_error)?;
        if !points.is_empty() {
            // Reference slopes through the geometric centre of the data.
            let n = points.len() as f64;
            let hc = (points.iter().map(|p| p.0.ln()).sum::<f64>() / n).exp();
            let ec = (points.iter().map(|p| p.1.ln()).sum::<f64>() / n).exp();
            for (k, &order) in self.slopes.iter().enumerate() {
                let grey = RGBColor(110, 110, 110);
                let line = [h0, h1].map(|h| (h, ec * (h / hc).powi(order as i32)));
                let dashes = dashed(line[0], line[1], 24);
                let style = grey.stroke_width(1 + k as u32);
                chart
                    .draw_series(
                        dashes
                            .into_iter()
                            .map(move |seg| PathElement::new(seg, style)),
                    )
                    .map_err(text_error)?
                    .label(format!("slope {order} (O(H^{order}))"))
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 8, y)], grey.stroke_width(1 + k as u32))
                    });
            }
        }
        for (i, curve) in self.curves.iter().enumerate() {
            let pts: Vec<(f64, f64)> = curve
                .points
                .iter()
                .filter(|p| p.error.is_finite() && p.error > 0.0)
                .map(|p| (p.step, p.error))
                .collect();
            let c = colour(i);
            let failed = curve.points.iter().filter(|p| !p.error.is_finite()).count();
            let mut label = match curve.order {
                Some(p) => format!("{}: order {p:.2}", curve.label),
                None => curve.label.clone(),
            };
            if failed > 0 {
                label += &format!(" ({failed} run(s) diverged or failed)");
            }
            chart
                .draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))
                .map_err(text_error)?
                .label(label)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(3))
                });
            chart
                .draw_series(pts.into_iter().map(|p| Circle::new(p, 4, c.filled())))
                .map_err(text_error)?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerRight)
            .background_style(WHITE.mix(0.9))
            .border_style(BLACK.mix(0.3))
            .label_font(("sans-serif", 15))
            .draw()
            .map_err(text_error)
    }
}

/// Split the segment a–b (straight on log-log axes) into `n` dashes.
fn dashed(a: (f64, f64), b: (f64, f64), n: usize) -> Vec<Vec<(f64, f64)>> {
    let at = |s: f64| {
        (
            (a.0.ln() + s * (b.0.ln() - a.0.ln())).exp(),
            (a.1.ln() + s * (b.1.ln() - a.1.ln())).exp(),
        )
    };
    (0..n)
        .map(|i| {
            let s = i as f64 / n as f64;
            vec![at(s), at(s + 0.6 / n as f64)]
        })
        .collect()
}
