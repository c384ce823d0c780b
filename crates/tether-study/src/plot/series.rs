//! Time series: one panel per column, one line per run.

use plotters::coord::Shift;
use plotters::prelude::*;

use super::{colour, padded_range, text_error, tick, tick_on, Figure};
use crate::Table;

/// Columns over time for one or more runs.
pub struct SeriesPlot<'a> {
    /// Figure title.
    pub title: String,
    /// The columns to draw, one panel each, top to bottom.
    pub columns: Vec<String>,
    /// The runs, with their legend labels.
    pub runs: Vec<(String, &'a Table)>,
    /// Units of columns, where known (as the FMUs declare them), for the
    /// axis labels: `mass1.x [m]`.
    pub units: Vec<(String, String)>,
}

impl Figure for SeriesPlot<'_> {
    fn size(&self) -> (u32, u32) {
        (960, 70 + 230 * self.columns.len().max(1) as u32)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let root = root
            .titled(&self.title, ("sans-serif", 24))
            .map_err(text_error)?;
        let panels = root.split_evenly((self.columns.len().max(1), 1));
        // Incomplete runs (diverged) would dwarf the others: ranges come from
        // the completed runs when there are any.
        let complete: Vec<&(String, &Table)> = self
            .runs
            .iter()
            .filter(|(_, t)| t.incomplete.is_none())
            .collect();
        let ranged = if complete.is_empty() {
            self.runs.iter().collect()
        } else {
            complete
        };
        let (t0, t1) = padded_range(
            self.runs
                .iter()
                .flat_map(|(_, t)| [t.times[0], *t.times.last().unwrap_or(&t.times[0])]),
        );
        for (p, (panel, column)) in panels.iter().zip(&self.columns).enumerate() {
            let (y0, y1) = padded_range(ranged.iter().flat_map(|(_, t)| {
                t.column(column)
                    .map(|c| t.values[c].clone())
                    .unwrap_or_default()
            }));
            let mut chart = ChartBuilder::on(panel)
                .margin(8)
                .x_label_area_size(36)
                .y_label_area_size(80)
                .build_cartesian_2d(t0.max(0.0).min(t0)..t1, y0..y1)
                .map_err(text_error)?;
            let y_desc = match self.units.iter().find(|(c, _)| c == column) {
                Some((_, unit)) => format!("{column} [{unit}]"),
                None => column.clone(),
            };
            let x_tick = |v: &f64| tick_on(*v, t1 - t0);
            let y_tick = |v: &f64| tick_on(*v, y1 - y0);
            chart
                .configure_mesh()
                .x_desc("time [s]")
                .y_desc(y_desc)
                .x_label_formatter(&x_tick)
                .y_label_formatter(&y_tick)
                .label_style(("sans-serif", 15))
                .axis_desc_style(("sans-serif", 17))
                .light_line_style(RGBColor(235, 235, 235))
                .draw()
                .map_err(text_error)?;
            for (i, (label, table)) in self.runs.iter().enumerate() {
                let Ok(c) = table.column(column) else {
                    continue;
                };
                let style = colour(i).stroke_width(2);
                let points = table
                    .times
                    .iter()
                    .copied()
                    .zip(table.values[c].iter().map(|v| {
                        if v.is_finite() {
                            v.clamp(y0 - (y1 - y0), y1 + (y1 - y0))
                        } else {
                            y1
                        }
                    }));
                let series = chart
                    .draw_series(LineSeries::new(points, style))
                    .map_err(text_error)?;
                if p == 0 {
                    let label = match &table.incomplete {
                        Some(_) => format!(
                            "{label} (stopped at t = {})",
                            tick(table.times.last().unwrap_or(&0.0))
                        ),
                        None => label.clone(),
                    };
                    series.label(label).legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], colour(i).stroke_width(3))
                    });
                }
            }
            if p == 0 && (self.runs.len() > 1 || !self.runs[0].0.is_empty()) {
                chart
                    .configure_series_labels()
                    .position(SeriesLabelPosition::UpperRight)
                    .background_style(WHITE.mix(0.85))
                    .border_style(BLACK.mix(0.3))
                    .label_font(("sans-serif", 15))
                    .draw()
                    .map_err(text_error)?;
            }
        }
        Ok(())
    }
}
