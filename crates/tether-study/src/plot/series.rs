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

/// The figure's width in pixels.
const WIDTH: u32 = 960;

/// Title text size in pixels.
const TITLE_SIZE: f64 = 24.0;

/// Height of a title line after the first.
const TITLE_LINE: u32 = 30;

impl SeriesPlot<'_> {
    /// The title in lines that fit the figure's width (with a margin),
    /// broken after commas where it can, else at spaces; one line when it
    /// fits.
    fn title_lines(&self) -> Vec<String> {
        let font = ("sans-serif", TITLE_SIZE).into_font();
        let fits = |text: &str| font.box_size(text).map_or(true, |(w, _)| w + 40 <= WIDTH);
        if fits(&self.title) {
            return vec![self.title.clone()];
        }
        // Pieces that end after a comma (or a space where there is none).
        let pieces: Vec<String> = if self.title.contains(", ") {
            self.title
                .split_inclusive(", ")
                .map(str::to_string)
                .collect()
        } else {
            self.title
                .split_inclusive(' ')
                .map(str::to_string)
                .collect()
        };
        let mut lines: Vec<String> = vec![String::new()];
        for piece in pieces {
            let last = lines.last_mut().expect("a line");
            let joined = format!("{last}{piece}");
            if last.is_empty() || fits(joined.trim_end()) {
                *last = joined;
            } else {
                lines.push(piece);
            }
        }
        lines.iter().map(|l| l.trim_end().to_string()).collect()
    }
}

impl Figure for SeriesPlot<'_> {
    fn size(&self) -> (u32, u32) {
        let extra = TITLE_LINE * (self.title_lines().len() as u32 - 1);
        (WIDTH, 70 + extra + 230 * self.columns.len().max(1) as u32)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let lines = self.title_lines();
        let root = if lines.len() == 1 {
            root.titled(&self.title, ("sans-serif", TITLE_SIZE))
                .map_err(text_error)?
        } else {
            // A long title on several centred lines, none clipped.
            let height = 14 + TITLE_LINE * lines.len() as u32;
            let (top, rest) = root.split_vertically(height);
            let style = ("sans-serif", TITLE_SIZE).into_font().color(&BLACK).pos(
                plotters::style::text_anchor::Pos::new(
                    plotters::style::text_anchor::HPos::Center,
                    plotters::style::text_anchor::VPos::Top,
                ),
            );
            for (i, line) in lines.iter().enumerate() {
                top.draw(&Text::new(
                    line.clone(),
                    ((WIDTH / 2) as i32, 8 + (TITLE_LINE as i32) * i as i32),
                    style.clone(),
                ))
                .map_err(text_error)?;
            }
            rest
        };
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
                        Some(_) if label.is_empty() => format!(
                            "stopped at t = {}",
                            tick(table.times.last().unwrap_or(&0.0))
                        ),
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
            // The legend names the runs; one unnamed run (the title names
            // it) gets one only to say where it stopped.
            let stopped = self.runs.len() == 1 && self.runs[0].1.incomplete.is_some();
            if p == 0 && (self.runs.len() > 1 || !self.runs[0].0.is_empty() || stopped) {
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

#[cfg(test)]
mod tests {
    use super::*;

    fn plot(title: &str) -> SeriesPlot<'static> {
        SeriesPlot {
            title: title.into(),
            columns: vec!["x".into()],
            runs: Vec::new(),
            units: Vec::new(),
        }
    }

    /// The titles of the paper's time-series figures fit on one line (their
    /// figures are drawn as before); a longer one is broken after commas.
    #[test]
    fn titles_fit_the_figure() {
        super::super::register_font();
        let root =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/figures/studies");
        for entry in std::fs::read_dir(root).unwrap() {
            let text = std::fs::read_to_string(entry.unwrap().path()).unwrap();
            if !text.contains("[series]") {
                continue;
            }
            let title = text
                .lines()
                .find_map(|l| l.strip_prefix("title = \""))
                .and_then(|t| t.strip_suffix('"'))
                .unwrap();
            assert_eq!(plot(title).title_lines(), [title]);
        }
        let long = "controlled two-mass oscillator: baumgarte (index 1, beta = 2e-3, \
                    gamma = 1e-6), signals: Jacobi, k = 1, H = 0.001";
        let lines = plot(long).title_lines();
        assert_eq!(
            lines,
            [
                "controlled two-mass oscillator: baumgarte (index 1, beta = 2e-3, gamma = 1e-6),",
                "signals: Jacobi, k = 1, H = 0.001",
            ]
        );
        assert_eq!(plot(long).size().1, 70 + TITLE_LINE + 230);
    }
}
