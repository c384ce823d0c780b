//! Stability maps: one panel per variant, one coloured cell per grid point.

use plotters::coord::Shift;
use plotters::prelude::*;

use super::{text_error, tick, tick2, Figure};
use crate::axis::{Axis, Scale};
use crate::stability::{Class, StabilityMap};

/// Stability maps of several variants over the same grid.
pub struct StabilityPlot<'a> {
    /// Figure title.
    pub title: String,
    /// Horizontal axis.
    pub x: &'a Axis,
    /// Vertical axis.
    pub y: &'a Axis,
    /// One map per panel.
    pub maps: &'a [StabilityMap],
}

const STABLE: RGBColor = RGBColor(120, 190, 120);
const UNSTABLE: RGBColor = RGBColor(215, 80, 70);
const FAILED: RGBColor = RGBColor(170, 170, 170);

impl StabilityPlot<'_> {
    fn grid(&self) -> (usize, usize) {
        let n = self.maps.len().max(1);
        let cols = if n == 1 { 1 } else { 2 };
        (n.div_ceil(cols), cols)
    }
}

/// Plot coordinate of a value: log10 on a log axis.
fn coord(scale: Scale, v: f64) -> f64 {
    match scale {
        Scale::Log => v.log10(),
        Scale::Linear => v,
    }
}

/// Cell edges in plot coordinates: midpoints between neighbours.
fn edges(scale: Scale, values: &[f64]) -> Vec<f64> {
    let c: Vec<f64> = values.iter().map(|&v| coord(scale, v)).collect();
    if c.len() == 1 {
        return vec![c[0] - 0.5, c[0] + 0.5];
    }
    let mut e = vec![c[0] - (c[1] - c[0]) / 2.0];
    e.extend(c.windows(2).map(|w| (w[0] + w[1]) / 2.0));
    let n = c.len();
    e.push(c[n - 1] + (c[n - 1] - c[n - 2]) / 2.0);
    e
}

impl Figure for StabilityPlot<'_> {
    fn size(&self) -> (u32, u32) {
        let (rows, cols) = self.grid();
        (60 + 560 * cols as u32, 110 + 470 * rows as u32)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let (xs, ys) = (
            self.x.values().map_err(text_error)?,
            self.y.values().map_err(text_error)?,
        );
        let (xe, ye) = (edges(self.x.scale, &xs), edges(self.y.scale, &ys));
        let root = root
            .titled(
                &self.title,
                ("sans-serif", if self.maps.len() > 1 { 22 } else { 17 }),
            )
            .map_err(text_error)?;
        let (body, footer) = root.split_vertically(root.dim_in_pixel().1 as i32 - 44);
        let legend = [
            (STABLE, "stable"),
            (UNSTABLE, "unstable (diverged or grew)"),
            (FAILED, "failed (other error)"),
        ];
        for (i, (c, text)) in legend.iter().enumerate() {
            let x = 20 + [0, 130, 400][i];
            footer
                .draw(&Rectangle::new([(x, 10), (x + 22, 30)], c.filled()))
                .map_err(text_error)?;
            footer
                .draw(&Text::new(*text, (x + 30, 12), ("sans-serif", 16)))
                .map_err(text_error)?;
        }
        let (xscale, yscale) = (self.x.scale, self.y.scale);
        let fmt_x = move |v: &f64| match xscale {
            Scale::Log => tick2(&10f64.powf(*v)),
            Scale::Linear => tick(v),
        };
        let fmt_y = move |v: &f64| match yscale {
            Scale::Log => tick2(&10f64.powf(*v)),
            Scale::Linear => tick(v),
        };
        for (panel, map) in body.split_evenly(self.grid()).iter().zip(self.maps) {
            let mut chart = ChartBuilder::on(panel)
                .caption(&map.label, ("sans-serif", 18))
                .margin(10)
                .x_label_area_size(44)
                .y_label_area_size(70)
                .build_cartesian_2d(xe[0]..xe[xe.len() - 1], ye[0]..ye[ye.len() - 1])
                .map_err(text_error)?;
            chart
                .configure_mesh()
                .disable_mesh()
                .x_desc(self.x.title())
                .y_desc(self.y.title())
                .x_label_formatter(&fmt_x)
                .y_label_formatter(&fmt_y)
                .label_style(("sans-serif", 14))
                .axis_desc_style(("sans-serif", 16))
                .draw()
                .map_err(text_error)?;
            let cells = map.cells.iter().enumerate().map(|(k, cell)| {
                let (i, j) = (k % xs.len(), k / xs.len());
                let colour = match cell.class {
                    Class::Stable => STABLE,
                    Class::Unstable => UNSTABLE,
                    Class::Failed => FAILED,
                };
                Rectangle::new([(xe[i], ye[j]), (xe[i + 1], ye[j + 1])], colour.filled())
            });
            chart.draw_series(cells).map_err(text_error)?;
            // Thin white grid lines between the cells.
            let lines = xe
                .iter()
                .map(|&x| vec![(x, ye[0]), (x, ye[ye.len() - 1])])
                .chain(ye.iter().map(|&y| vec![(xe[0], y), (xe[xe.len() - 1], y)]));
            chart
                .draw_series(lines.map(|l| PathElement::new(l, WHITE.stroke_width(1))))
                .map_err(text_error)?;
        }
        Ok(())
    }
}
