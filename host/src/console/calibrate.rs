//! Calibration from the host, with the requests and registers every unit has: no new firmware.
//!
//! - **mm per motor revolution** (0x42): a preloaded slot is ejected (`E`) with its filament kept
//!   gripped: between the park position and the slot sensor clearing, the unit's odometry
//!   (0xb0+k) counts the path from the hub sensor to the slot sensor minus the park distance
//!   (0x41, counted in the same units). That path's real length is known from the build
//!   (`--slot-to-hub-mm`), so the ratio corrects the unit's mm per revolution. Every slot with
//!   filament is measured; the mean is saved.
//! - **Bowden length** (0x22): from the park position a tool change runs with the fast part of
//!   the Bowden feed set to nothing, so the whole tube is fed slowly while the printer's filament
//!   sensor is watched (the simulator's, the `--fsensor-events` file's, or the person pressing
//!   Enter); the odometry when it triggers, less the park distance, is the length. The search is
//!   bounded by `--max-bowden-mm`; the unit's own bounds stay in force.
//! - **thresholds** (0x90+i on, 0xa0+i off) of every presence sensor: the filtered levels
//!   (0x70+i) with and without filament, measured during the two runs above; `on` and `off` sit at
//!   60 % and 40 % of the way from the empty to the full level.
//! - **park distance** (0x41): the unit has no sensor where the slot paths join, so it is the
//!   distance from the hub sensor back to the join (`--merge-mm`, measured on the hub) plus a
//!   margin, checked by preloading every parked slot (a tip left past the join would block the
//!   next).
//!
//! Every result is written to the unit, which saves it, and printed.

use std::str::FromStr;

use clap::ValueEnum;
use mmu_protocol::{ParamCode, Request, RequestCode};
use mmu_sim::Link;

use super::person::EjectDialog;
use super::{Bench, FsensorMode};

/// Distance from the hub sensor to each slot sensor on the reference unit, mm (the model's
/// `slot_sensor_mm`).
pub const SLOT_TO_HUB_MM: f64 = 95.0;
/// Longest Bowden feed while searching for the printer's sensor, mm.
pub const MAX_BOWDEN_MM: u16 = 1000;
/// Clearance of a parked tip beyond the join of the slot paths, mm.
pub const PARK_MARGIN_MM: u16 = 5;
/// Level readings averaged per measurement.
const SAMPLES: usize = 12;
/// Between two readings, ms.
const SAMPLE_GAP_MS: u64 = 20;
/// How far the simulated user pushes an ejected filament back in, mm.
const PUSH_BACK_MM: f32 = 5.0;
/// Wait for the sensors' filters after filament moved by hand, ms.
const SETTLE_MS: u64 = 300;
/// The Bowden register's smallest value; the fast part is set to the same, so it is nothing.
const BOWDEN_MIN_MM: u16 = 50;

/// What to calibrate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Step {
    /// Everything below, in order (park only with --merge-mm).
    All,
    /// Filament per motor revolution, from the slot-to-hub distance.
    MmPerRev,
    /// The Bowden length, to the printer's filament sensor.
    Bowden,
    /// The presence sensors' on/off thresholds.
    Thresholds,
    /// The park distance, from --merge-mm.
    Park,
}

impl FromStr for Step {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        <Step as ValueEnum>::from_str(text, true)
    }
}

/// How to calibrate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrateOptions {
    /// The slot the Bowden is measured with.
    pub slot: u8,
    /// The real distance from the hub sensor to a slot sensor, mm.
    pub slot_to_hub_mm: f64,
    /// The longest Bowden feed, mm.
    pub max_bowden_mm: u16,
    /// The distance from the hub sensor back to where the slot paths join, mm.
    pub merge_mm: Option<u16>,
}

impl Default for CalibrateOptions {
    fn default() -> Self {
        CalibrateOptions {
            slot: 0,
            slot_to_hub_mm: SLOT_TO_HUB_MM,
            max_bowden_mm: MAX_BOWDEN_MM,
            merge_mm: None,
        }
    }
}

/// A sensor's level: the mean filtered reading and the raw readings' spread (robust to spikes).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Level {
    /// Mean filtered reading, counts.
    pub mean: f64,
    /// Standard deviation of the raw readings, counts.
    pub sigma: f64,
}

/// What calibration saved.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Results {
    /// Register 0x42.
    pub mm_per_rev_centi: Option<u16>,
    /// Register 0x22.
    pub bowden_mm: Option<u16>,
    /// Register 0x41.
    pub park_mm: Option<u16>,
    /// Sensor index, on, off.
    pub thresholds: Vec<(u8, u16, u16)>,
}

/// One slot's eject run.
struct SlotRun {
    slot: u8,
    /// Odometry from the park position to the slot sensor clearing, plus the park travel.
    path_mm: f64,
    present: Level,
    absent: Level,
}

/// The diagnostic index of slot `slot`'s filament sensor (hub filament is 0).
/// Register 0x8d's bit for a hub sensor ([`mmu_firmware::profile::Profile::code`]).
const HUB_SENSOR_BIT: u16 = 1 << 4;

fn slot_sensor(slot: u8) -> u8 {
    3 + 2 * slot
}

/// Run `step` and save what it measures.
pub fn run(bench: &mut Bench, step: Step, options: &CalibrateOptions) -> Result<Results, String> {
    if options.slot >= bench.slots() {
        return Err(format!(
            "slot {}: the unit has {} slots (0-{})",
            options.slot,
            bench.slots(),
            bench.slots().saturating_sub(1)
        ));
    }
    // Every step measures against the hub sensor (an older firmware without register 0x8d has
    // one).
    let hub_sensor = bench
        .read(mmu_firmware::registers::HARDWARE)
        .map_or(true, |code| code & HUB_SENSOR_BIT != 0);
    if !hub_sensor {
        return Err(
            "this unit has no hub sensor (its hardware profile tells FINDA from each lane's odometry): the \
             calibration measures from the hub sensor and cannot run; set mm_per_rev_centi (0x42) from the drive \
             gear's effective diameter (π × diameter × 100) and lane_to_hub_mm (0x5f) from the build"
                .into(),
        );
    }
    idle(bench)?;
    let mut results = Results::default();
    let wants = |s: Step| step == Step::All || step == s;
    let mut runs = Vec::new();
    let mut hub_absent = None;
    if wants(Step::MmPerRev) || wants(Step::Thresholds) {
        for slot in 0..bench.slots() {
            if !has_filament(bench, slot)? {
                bench.say(&format!("slot {slot}: no filament, skipped"));
                continue;
            }
            hub_absent.get_or_insert(level(bench, 0)?);
            runs.push(eject_run(bench, slot)?);
        }
        if runs.is_empty() {
            return Err("no slot has filament: load one first".into());
        }
    }
    if wants(Step::MmPerRev) {
        results.mm_per_rev_centi = Some(save_mm_per_rev(bench, &runs, options)?);
    }
    let mut hub_present = None;
    if wants(Step::Bowden) {
        let (bowden, level) = measure_bowden(bench, options)?;
        hub_present = level;
        results.bowden_mm = Some(bowden);
    } else if wants(Step::Thresholds) {
        hub_present = Some(hub_level_loaded(bench, options.slot)?);
    }
    if wants(Step::Thresholds) {
        for run in &runs {
            let (on, off) = save_thresholds(bench, slot_sensor(run.slot), run.present, run.absent)?;
            results.thresholds.push((slot_sensor(run.slot), on, off));
        }
        if let (Some(present), Some(absent)) = (hub_present, hub_absent) {
            let (on, off) = save_thresholds(bench, 0, present, absent)?;
            results.thresholds.push((0, on, off));
        }
    }
    if wants(Step::Park) {
        match options.merge_mm {
            Some(merge) => results.park_mm = Some(save_park(bench, merge)?),
            None if step == Step::Park => {
                return Err("park needs --merge-mm: the distance from the hub sensor back to where the slot paths join".into());
            }
            None => bench.say("park distance: unchanged (give the hub's --merge-mm to set it)"),
        }
    }
    bench.say("calibration saved in the unit");
    Ok(results)
}

/// The unit must be at rest.
fn idle(bench: &mut Bench) -> Result<(), String> {
    let state = bench.request(Request::new(RequestCode::Query, 0))?;
    if state.param == ParamCode::Finished {
        Ok(())
    } else {
        bench.describe_state(&state);
        Err("calibration needs the unit at rest".into())
    }
}

/// Whether `slot` has filament: parked, loaded, or its sensor sees it.
fn has_filament(bench: &mut Bench, slot: u8) -> Result<bool, String> {
    let lane = bench.read(0xb8 + slot)?;
    if lane != 0 {
        return Ok(true);
    }
    let index = slot_sensor(slot);
    let (filtered, on) = (bench.read(0x70 + index)?, bench.read(0x90 + index)?);
    Ok(filtered >= on)
}

/// The slot's filament parked before the hub (unloading what is loaded first).
fn park(bench: &mut Bench, slot: u8) -> Result<(), String> {
    if bench.read(0x08)? != 0 {
        bench.command(Request::new(RequestCode::Unload, 0))?;
    }
    if bench.read(0xb8 + slot)? != 1 {
        bench.command(Request::new(RequestCode::Load, slot))?;
    }
    Ok(())
}

/// The slot's odometry, mm (signed; it wraps: see [`odometry_moved`]).
fn odometry(bench: &mut Bench, slot: u8) -> Result<i32, String> {
    Ok(i32::from(bench.read(0xb0 + slot)? as i16))
}

/// The filament moved from odometry reading `from` to `to`, mm: their difference wrapped to 16
/// bits as the register is (a plain difference was off by 65 536 mm across its end).
fn odometry_moved(from: i32, to: i32) -> i32 {
    i32::from((to as i16).wrapping_sub(from as i16))
}

/// How far the unit's odometry runs past the hub sensor clearing when it parks, mm: the park
/// distance rounded up to whole motor revolutions (odometry moves one revolution at a time).
fn park_travel(bench: &mut Bench) -> Result<f64, String> {
    let park_centi = u32::from(bench.read(0x41)?) * 100;
    let step = u32::from(bench.read(0x42)?.max(1));
    Ok(f64::from(park_centi.div_ceil(step) * step) / 100.0)
}

/// Sensor `index`'s level now.
fn level(bench: &mut Bench, index: u8) -> Result<Level, String> {
    let mut filtered = Vec::with_capacity(SAMPLES);
    let mut raw = Vec::with_capacity(SAMPLES);
    for _ in 0..SAMPLES {
        filtered.push(f64::from(bench.read(0x70 + index)?));
        raw.push(f64::from(bench.read(0x60 + index)?));
        bench.link().pause(SAMPLE_GAP_MS).map_err(|e| e.to_string())?;
    }
    let mean = filtered.iter().sum::<f64>() / filtered.len() as f64;
    Ok(Level {
        mean,
        sigma: robust_sigma(&mut raw),
    })
}

/// The spread of `values` as a standard deviation, from their median absolute deviation: one
/// spike among the readings (the filter's median removes those) does not count as noise.
fn robust_sigma(values: &mut [f64]) -> f64 {
    let median = |values: &mut [f64]| {
        values.sort_by(f64::total_cmp);
        values.get(values.len() / 2).copied().unwrap_or(0.0)
    };
    let centre = median(values);
    let mut deviations: Vec<f64> = values.iter().map(|v| (v - centre).abs()).collect();
    1.4826 * median(&mut deviations)
}

/// Park `slot`, eject it with its filament kept gripped, measure, and put it back.
fn eject_run(bench: &mut Bench, slot: u8) -> Result<SlotRun, String> {
    park(bench, slot)?;
    let present = level(bench, slot_sensor(slot))?;
    let parked_at = odometry(bench, slot)?;
    let park_mm = park_travel(bench)?;
    bench.person.eject = EjectDialog::KeepIn;
    let ejected = bench.command(Request::new(RequestCode::Eject, slot));
    bench.person.eject = EjectDialog::TakeOut;
    ejected?;
    let cleared_at = odometry(bench, slot)?;
    let absent = level(bench, slot_sensor(slot))?;
    put_back(bench, slot)?;
    Ok(SlotRun {
        slot,
        path_mm: f64::from(odometry_moved(cleared_at, parked_at)) + park_mm,
        present,
        absent,
    })
}

/// The ejected filament goes back in until the slot sensor sees it, then is parked.
fn put_back(bench: &mut Bench, slot: u8) -> Result<(), String> {
    let pushed = bench.link().sim_mut().is_some_and(|sim| {
        let model = sim.model_mut();
        let tip = model.tip_mm(usize::from(slot));
        tip.is_some_and(|tip| model.insert_filament(usize::from(slot), tip + PUSH_BACK_MM))
    });
    if pushed {
        bench.say(&format!(
            "the simulated user pushes slot {slot}'s filament back in by {PUSH_BACK_MM} mm"
        ));
    } else {
        bench.say(&format!(
            "Push slot {slot}'s filament back in by about 5 mm, until the slot sensor sees it, then press Enter."
        ));
        if bench.person.line("calibrate> ").is_none() {
            return Err("no answer: calibration stopped".into());
        }
    }
    // The slot sensor's filter needs a moment to see it.
    bench.link().pause(SETTLE_MS).map_err(|e| e.to_string())?;
    bench.command(Request::new(RequestCode::Load, slot))
}

/// Save the mean mm per revolution the runs give.
fn save_mm_per_rev(bench: &mut Bench, runs: &[SlotRun], options: &CalibrateOptions) -> Result<u16, String> {
    let was = bench.read(0x42)?;
    let known = options.slot_to_hub_mm;
    let mut values = Vec::new();
    for run in runs {
        let counted = run.path_mm;
        if !(known / 3.0..=known * 3.0).contains(&counted) {
            return Err(format!(
                "slot {}: the unit counted {counted:.1} mm for the {known} mm from the hub sensor to the slot sensor: \
                 check the motor's Hall sensor thresholds and --slot-to-hub-mm",
                run.slot
            ));
        }
        let centi = f64::from(was) * known / counted;
        bench.say(&format!(
            "slot {}: the unit counted {counted:.1} mm for the {known} mm from the hub sensor to the slot sensor: {:.2} mm per motor revolution",
            run.slot,
            centi / 100.0
        ));
        values.push(centi);
    }
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    let centi = mean.round().clamp(10.0, 5000.0) as u16;
    bench.write(0x42, centi)?;
    bench.say(&format!(
        "mm per motor revolution: {:.2} (register 0x42 = {centi}, was {was})",
        f64::from(centi) / 100.0
    ));
    Ok(centi)
}

/// Feed slot `options.slot` from its park position until the printer's sensor triggers; save the
/// length. Also the hub sensor's level with filament, measured while it is loaded.
fn measure_bowden(bench: &mut Bench, options: &CalibrateOptions) -> Result<(u16, Option<Level>), String> {
    let slot = options.slot;
    park(bench, slot)?;
    let was = bench.read(0x22)?;
    let saved = [(0x4a, bench.read(0x4a)?), (0x48, bench.read(0x48)?)];
    let search = options
        .max_bowden_mm
        .saturating_sub(BOWDEN_MIN_MM)
        .clamp(10, 2000);
    bench.write(0x4a, BOWDEN_MIN_MM)?;
    bench.write(0x22, BOWDEN_MIN_MM)?;
    bench.write(0x48, search)?;
    let measured = feed_to_fsensor(bench, slot, options);
    let restored = saved
        .iter()
        .try_for_each(|&(address, value)| bench.write(address, value));
    let (length, hub_present) = match measured {
        Ok(found) => found,
        Err(error) => {
            bench.write(0x22, was)?;
            return Err(error);
        }
    };
    restored?;
    let length = u16::try_from(length)
        .ok()
        .filter(|&l| l >= BOWDEN_MIN_MM)
        .ok_or_else(|| format!("a Bowden length of {length} mm makes no sense: nothing saved"))?;
    bench.write(0x22, length)?;
    bench.say(&format!("Bowden length: {length} mm (register 0x22, was {was})"));
    Ok((length, hub_present))
}

/// The tool change with the slow search; the odometry at the printer's sensor less the park
/// position, and the hub's level while loaded.
fn feed_to_fsensor(
    bench: &mut Bench,
    slot: u8,
    options: &CalibrateOptions,
) -> Result<(i32, Option<Level>), String> {
    let started_at = odometry(bench, slot)?;
    let park_mm = park_travel(bench)?;
    let speed = u64::from(bench.read(0x14)?.max(1));
    let by_key =
        bench.link().sim().is_none() && !bench.fsensor_events && bench.link().fsensor == FsensorMode::Auto;
    if bench.link().fsensor() != 0 {
        return Err(
            "the printer's filament sensor already sees filament: clear the Bowden tube first".into(),
        );
    }
    bench.request(Request::new(RequestCode::FilamentSensor, 0))?;
    let enter = by_key.then(|| {
        bench.say(&format!(
            "Press Enter the moment the filament reaches the printer's filament sensor (feeding at {speed} mm/s, at most {} mm).",
            options.max_bowden_mm
        ));
        bench.person.input.watch_enter()
    });
    let tool = Request::new(RequestCode::Tool, slot);
    let answer = bench.request(tool)?;
    if answer.param != ParamCode::Accepted {
        return Err("the unit refused the tool change".into());
    }
    let found = watch_fsensor(bench, slot, options, speed, enter.as_ref());
    if let (Err(_), Some(enter)) = (&found, &enter) {
        bench.say("Press Enter to go on.");
        let _ = enter.recv();
    }
    let triggered_at = found?;
    if by_key {
        bench.link().fsensor = FsensorMode::Fixed(1);
        bench.request(Request::new(RequestCode::FilamentSensor, 1))?;
    }
    let outcome = bench
        .printer
        .follow(&mut bench.person, tool)
        .map_err(|e| e.to_string())?;
    bench.outcome(tool, outcome, None)?;
    let hub = level(bench, 0)?;
    if by_key {
        bench.say("the printer's filament sensor now reads off as the filament comes back");
        bench.link().fsensor = FsensorMode::Fixed(0);
    }
    let unloaded = bench.command(Request::new(RequestCode::Unload, 0));
    if by_key {
        bench.link().fsensor = FsensorMode::Auto;
    }
    unloaded?;
    Ok((
        (f64::from(odometry_moved(started_at, triggered_at)) - park_mm).round() as i32,
        Some(hub),
    ))
}

/// Poll the running tool change until the printer's sensor (or the person's Enter) says the tip
/// is there; the odometry then, read before the unit is told (it stops searching when it is).
fn watch_fsensor(
    bench: &mut Bench,
    slot: u8,
    options: &CalibrateOptions,
    speed: u64,
    enter: Option<&std::sync::mpsc::Receiver<String>>,
) -> Result<i32, String> {
    let bound_ms = u64::from(options.max_bowden_mm) * 2000 / speed + 10_000;
    let deadline = bench.link().now_ms() + bound_ms;
    let mut next_query = 0;
    loop {
        let triggered = match enter {
            Some(enter) => enter.try_recv().is_ok(),
            None => bench.link().fsensor() != 0,
        };
        if triggered {
            let at = odometry(bench, slot)?;
            let state = bench.link().fsensor();
            if enter.is_none() {
                bench.request(Request::new(RequestCode::FilamentSensor, state))?;
            }
            return Ok(at);
        }
        let now = bench.link().now_ms();
        if now >= next_query {
            next_query = now + 200;
            let state = bench.request(Request::new(RequestCode::Query, 0))?;
            if state.param != ParamCode::Processing {
                bench.describe_state(&state);
                return Err(format!(
                    "the printer's filament sensor was not seen within {} mm",
                    options.max_bowden_mm
                ));
            }
        }
        if now > deadline {
            return Err("the printer's filament sensor was not seen in time".into());
        }
        bench.link().pause(5).map_err(|e| e.to_string())?;
    }
}

/// The hub sensor's level with `slot` loaded (for thresholds alone).
fn hub_level_loaded(bench: &mut Bench, slot: u8) -> Result<Level, String> {
    bench.command(Request::new(RequestCode::Tool, slot))?;
    let hub = level(bench, 0)?;
    bench.command(Request::new(RequestCode::Unload, 0))?;
    Ok(hub)
}

/// On and off thresholds between the levels without and with filament.
pub fn thresholds(present: Level, absent: Level) -> Result<(u16, u16), String> {
    let span = present.mean - absent.mean;
    let noise = present.sigma.max(absent.sigma);
    if span < 0.0 {
        return Err(format!(
            "reads lower with filament ({:.0}) than without ({:.0}): turn the magnet around",
            present.mean, absent.mean
        ));
    }
    if span < 100.0_f64.max(8.0 * noise) {
        return Err(format!(
            "barely changes with filament ({:.0} → {:.0}, noise {noise:.0}): bring the magnet closer to the sensor",
            absent.mean, present.mean
        ));
    }
    let at = |fraction: f64| (absent.mean + fraction * span).round().clamp(0.0, 4095.0) as u16;
    Ok((at(0.6), at(0.4)))
}

/// Compute and write sensor `index`'s thresholds, keeping off below on at every step.
fn save_thresholds(
    bench: &mut Bench,
    index: u8,
    present: Level,
    absent: Level,
) -> Result<(u16, u16), String> {
    let name = match index {
        0 => "hub filament sensor".to_string(),
        i => format!("slot {} filament sensor", (i - 3) / 2),
    };
    let (on, off) = thresholds(present, absent).map_err(|why| format!("{name}: {why}"))?;
    let current_on = bench.read(0x90 + index)?;
    if off < current_on {
        bench.write(0xa0 + index, off)?;
        bench.write(0x90 + index, on)?;
    } else {
        bench.write(0x90 + index, on)?;
        bench.write(0xa0 + index, off)?;
    }
    bench.say(&format!(
        "{name}: {:.0} without filament, {:.0} with (noise {:.0}): on {on}, off {off} (registers 0x{:02x}/0x{:02x})",
        absent.mean,
        present.mean,
        present.sigma.max(absent.sigma),
        0x90 + index,
        0xa0 + index
    ));
    Ok((on, off))
}

/// Save the park distance for a join `merge_mm` behind the hub sensor, and preload every parked
/// slot to check that none blocks the next.
fn save_park(bench: &mut Bench, merge_mm: u16) -> Result<u16, String> {
    let was = bench.read(0x41)?;
    let park_mm = merge_mm.saturating_add(PARK_MARGIN_MM).clamp(1, 200);
    bench.write(0x41, park_mm)?;
    let mut checked = Vec::new();
    for slot in 0..bench.slots() {
        if bench.read(0xb8 + slot)? == 1 {
            bench
                .command(Request::new(RequestCode::Load, slot))
                .map_err(|e| format!("slot {slot} could not pass with the new park distance: {e}"))?;
            checked.push(slot.to_string());
        }
    }
    let check = if checked.is_empty() {
        "no slot was parked, so none was checked: `load SLOT` each slot to check it".to_string()
    } else {
        format!("parked slot(s) {} preloaded again with it", checked.join(", "))
    };
    bench.say(&format!(
        "park distance: {park_mm} mm (register 0x41, was {was}); {check}"
    ));
    Ok(park_mm)
}

#[cfg(test)]
mod tests {
    use mmu_model::ModelConfig;
    use mmu_sim::{Sim, SimLink, SimOptions};

    use super::super::input::Input;
    use super::super::link::Wire;
    use super::*;

    /// The odometry register wraps at 16 bits: a move across its end is the short way round.
    #[test]
    fn odometry_moved_wraps_with_the_register() {
        assert_eq!(odometry_moved(10, 250), 240);
        assert_eq!(odometry_moved(250, 10), -240);
        assert_eq!(odometry_moved(32_700, -32_700), 136);
        assert_eq!(odometry_moved(-32_700, 32_700), -136);
    }

    /// A connected bench on a simulated unit built as `model`, its settings at their defaults.
    fn bench(model: ModelConfig) -> Bench {
        let sim = Sim::new(SimOptions {
            model,
            ..SimOptions::default()
        })
        .unwrap();
        let wire = Wire::Sim(Box::new(SimLink::new(sim)));
        let mut bench = Bench::on_wire(wire, Default::default(), Input::Lines(Default::default()), false);
        bench.connect().unwrap();
        bench
    }

    /// A unit whose motors move 2.3 mm per revolution (the settings say 2.0) and whose Bowden tube
    /// is 450 mm (the settings say 360): calibration finds both within the odometry's resolution
    /// (one revolution, 2.3 mm, over the 95 mm slot-to-hub path: 3 %; the Bowden, in the unit's
    /// own mm, to two revolutions: the odometry lags by up to one at each end), and
    /// thresholds between the model's levels (2048 empty, 3000 with filament).
    #[test]
    fn finds_the_model_s_true_values() {
        let model = ModelConfig {
            mm_per_rev: 2.3,
            bowden_length_mm: 450.0,
            extruder_gears_mm: 454.0,
            nozzle_mm: 510.0,
            ..ModelConfig::default()
        };
        let mut bench = bench(model);
        let results = run(&mut bench, Step::All, &CalibrateOptions::default()).unwrap();
        let centi = results.mm_per_rev_centi.unwrap();
        assert!((223..=237).contains(&centi), "mm/rev × 100 = {centi}, truly 230");
        assert_eq!(bench.read(0x42), Ok(centi), "saved");
        // The unit measures the Bowden with its odometry as it will feed it: in its own mm.
        let bowden = results.bowden_mm.unwrap();
        let real = f64::from(bowden) * 2.3 / (f64::from(centi) / 100.0);
        assert!(
            (real - 450.0).abs() <= 4.6,
            "Bowden {bowden} unit mm = {real:.1} mm, truly 450"
        );
        assert_eq!(bench.read(0x22), Ok(bowden), "saved");
        assert_eq!(results.thresholds.len(), 4, "three slot sensors and the hub's");
        for &(index, on, off) in &results.thresholds {
            // 60 % and 40 % of the way from 2048 to 3000, give or take the noise.
            assert!(
                on.abs_diff(2619) <= 15 && off.abs_diff(2429) <= 15,
                "sensor {index}: on {on} off {off}"
            );
            assert_eq!(bench.read(0x90 + index), Ok(on));
            assert_eq!(bench.read(0xa0 + index), Ok(off));
        }
        // The unit works with what was saved: a tool change on the long Bowden.
        bench.command(Request::new(RequestCode::Tool, 2)).unwrap();
    }

    /// A setting that is wrong by a lot is corrected in one run; the feed never went past the
    /// bound.
    #[test]
    fn a_bowden_past_the_bound_is_not_searched_for() {
        let model = ModelConfig {
            bowden_length_mm: 700.0,
            extruder_gears_mm: 704.0,
            nozzle_mm: 760.0,
            ..ModelConfig::default()
        };
        let mut bench = bench(model);
        let options = CalibrateOptions {
            max_bowden_mm: 500,
            ..CalibrateOptions::default()
        };
        let error = run(&mut bench, Step::Bowden, &options).unwrap_err();
        assert!(error.contains("not seen within 500 mm"), "{error}");
        let tip = bench.link().sim().unwrap().model().tip_mm(0).unwrap();
        assert!(tip < 520.0, "the tip went to {tip} mm");
        assert_eq!(bench.read(0x22), Ok(360), "the old length is kept");
        assert_eq!(bench.read(0x48), Ok(90), "the search bound is restored");
    }

    /// The park distance follows the hub's join, and every parked slot still preloads.
    #[test]
    fn park_from_the_join() {
        let mut bench = bench(ModelConfig::default());
        let missing = run(&mut bench, Step::Park, &CalibrateOptions::default()).unwrap_err();
        assert!(missing.contains("--merge-mm"), "{missing}");
        for slot in 0..3 {
            bench.command(Request::new(RequestCode::Load, slot)).unwrap();
        }
        let options = CalibrateOptions {
            merge_mm: Some(8),
            ..CalibrateOptions::default()
        };
        let results = run(&mut bench, Step::Park, &options).unwrap();
        assert_eq!(results.park_mm, Some(8 + PARK_MARGIN_MM));
        assert_eq!(bench.read(0x41), Ok(13));
        for slot in 0..3 {
            let tip = bench.link().sim().unwrap().model().tip_mm(slot).unwrap();
            assert!(tip < -8.0, "slot {slot}'s tip at {tip} mm blocks the join");
        }
    }

    #[test]
    fn thresholds_between_the_levels() {
        let level = |mean, sigma| Level { mean, sigma };
        assert_eq!(
            thresholds(level(3000.0, 15.0), level(2000.0, 15.0)),
            Ok((2600, 2400))
        );
        assert!(
            thresholds(level(2000.0, 15.0), level(3000.0, 15.0))
                .unwrap_err()
                .contains("magnet around")
        );
        assert!(
            thresholds(level(2100.0, 15.0), level(2050.0, 15.0))
                .unwrap_err()
                .contains("closer")
        );
    }
}

#[cfg(test)]
mod noise_tests {
    use super::robust_sigma;

    #[test]
    fn one_spike_is_not_noise() {
        let mut readings = [2040.0, 2050.0, 2045.0, 2055.0, 2648.0, 2035.0, 2050.0, 2045.0];
        let sigma = robust_sigma(&mut readings);
        assert!(sigma < 15.0, "{sigma}");
    }
}
