//! `mmu sensors --plot`: the recorded trace as a PNG, one panel per sensor, raw and filtered
//! readings against the "on" and "off" thresholds, so a maker sees where the levels with and
//! without filament sit and moves the thresholds between them.
//!
//! Drawn with plotters' bitmap backend; the text uses DejaVu Sans from the `dejavu` crate, so no
//! system font is needed.

use std::error::Error;
use std::path::Path;
use std::sync::Once;

use plotters::prelude::*;
use plotters::style::FontStyle;

use super::{Sample, Thresholds, sensor_name};

/// Image size, pixels.
const WIDTH: u32 = 1600;
const HEIGHT: u32 = 1200;
/// The name the embedded font is registered under.
const FONT: &str = "sans-serif";

const RAW: RGBColor = RGBColor(150, 180, 230);
const FILTERED: RGBColor = RGBColor(20, 60, 160);
const ON: RGBColor = RGBColor(200, 40, 40);
const OFF: RGBColor = RGBColor(230, 140, 20);

fn register_font() -> Result<(), Box<dyn Error>> {
    static REGISTER: Once = Once::new();
    let mut result = Ok(());
    REGISTER.call_once(|| {
        result = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular())
            .map_err(|_| "the embedded font cannot be read".into());
    });
    result
}

/// Draw `samples` (with each sensor's `thresholds`) to the PNG `file`.
pub fn draw(
    file: &Path,
    samples: &[Sample],
    thresholds: &[Option<Thresholds>],
) -> Result<(), Box<dyn Error>> {
    if samples.is_empty() {
        return Err("no sample was recorded: nothing to draw".into());
    }
    register_font()?;
    let sensors = thresholds.len();
    let root = BitMapBackend::new(file, (WIDTH, HEIGHT)).into_drawing_area();
    root.fill(&WHITE)?;
    let (title, body) = root.split_vertically(50);
    let end_s = samples.last().map_or(0.0, |s| s.t_ms as f64 / 1000.0);
    title.draw_text(
        &format!(
            "mmu sensors: {} samples over {end_s:.1} s   light blue raw, dark blue filtered, red \"on\" threshold, orange \"off\" threshold (ADC counts)",
            samples.len()
        ),
        &(FONT, 20).into_font().color(&BLACK),
        (15, 15),
    )?;
    let columns = sensors.clamp(1, 3);
    let rows = sensors.div_ceil(columns).max(1);
    let panels = body.split_evenly((rows, columns));
    for (position, panel) in panels.iter().enumerate().take(sensors) {
        let limits = thresholds.get(position).copied().flatten();
        draw_panel(panel, position, samples, limits, end_s)?;
    }
    root.present()
        .map_err(|error| format!("cannot write {}: {error}", file.display()))?;
    Ok(())
}

/// One sensor's panel: the sensor at `position` in each sample.
fn draw_panel<DB: DrawingBackend>(
    panel: &DrawingArea<DB, plotters::coord::Shift>,
    position: usize,
    samples: &[Sample],
    limits: Option<Thresholds>,
    end_s: f64,
) -> Result<(), Box<dyn Error>>
where
    DB::ErrorType: 'static,
{
    let reading = |sample: &Sample| sample.readings.get(position).copied();
    let mut low = u16::MAX;
    let mut high = 0u16;
    for r in samples.iter().filter_map(reading) {
        low = low.min(r.raw.min(r.filtered));
        high = high.max(r.raw.max(r.filtered));
    }
    if let Some(t) = limits {
        low = low.min(t.off);
        high = high.max(t.on);
    }
    // Room around the traces, within the ADC's range.
    let margin = ((high.saturating_sub(low)) / 10).max(50);
    let (y_low, y_high) = (low.saturating_sub(margin), high.saturating_add(margin).min(4095));
    let mut name = samples
        .iter()
        .find_map(&reading)
        .map_or_else(String::new, |r| sensor_name(r.id));
    // The unit stops believing a sensor stuck at a rail: say so where the trace shows it.
    if let Some(first) = samples.iter().find(|s| reading(s).is_some_and(|r| r.stuck)) {
        name.push_str(&format!(
            ": STUCK AT A RAIL from {:.1} s, check its wiring",
            first.t_ms as f64 / 1000.0
        ));
    }
    let caption_color = if name.contains("STUCK") { ON } else { BLACK };
    let mut chart = ChartBuilder::on(panel)
        .caption(&name, (FONT, 20).into_font().color(&caption_color))
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(55)
        .build_cartesian_2d(
            0.0..end_s.max(0.1),
            f64::from(y_low)..f64::from(y_high.max(y_low + 1)),
        )?;
    chart
        .configure_mesh()
        .x_desc("s")
        .y_label_formatter(&|counts| format!("{counts:.0}"))
        .label_style((FONT, 13))
        .x_labels(6)
        .y_labels(6)
        .draw()?;
    let points = |value: fn(&super::Reading) -> u16| {
        samples
            .iter()
            .filter_map(move |s| reading(s).map(|r| (s.t_ms as f64 / 1000.0, f64::from(value(&r)))))
    };
    chart.draw_series(LineSeries::new(points(|r| r.raw), RAW.stroke_width(1)))?;
    chart.draw_series(LineSeries::new(points(|r| r.filtered), FILTERED.stroke_width(2)))?;
    if let Some(t) = limits {
        for (level, color) in [(t.on, ON), (t.off, OFF)] {
            let line = [(0.0, f64::from(level)), (end_s, f64::from(level))];
            chart.draw_series(LineSeries::new(line, color.stroke_width(2)))?;
        }
    }
    Ok(())
}
