//! `mmu sensors`: every sensor of a unit live, to check the wiring at first power-on and to tune
//! the thresholds: a table refreshed in place, CSV rows (`--csv`), or a recorded trace drawn to a
//! PNG (`--plot FILE.png --seconds N`, in [`plot`]).
//!
//! It only reads (the printer's handshake without its writes, then `R` requests): raw readings
//! at `0x60 + i`, filtered at `0x70 + i`, "on"/"off" thresholds at `0x90 + i`/`0xa0 + i` and the
//! stuck-at-a-rail mask at `0x50`. Sensor `i`: 0 hub filament, 1 hub tension, 2 hub cutter, then
//! slot `k`'s filament sensor at `3 + 2k` and its motion sensor at `4 + 2k`, then each lane's
//! tension sensor (`mmu_firmware::unit::SensorId::index`). Only the sensors the unit's hardware
//! has are shown: those whose raw reading it answers.
//!
//! Each reading is a request and its answer, about a millisecond apiece on the wire: the nine
//! sensors of a 3-slot thesis build take some 19 ms a sample, so `--sensor NAME` reads only the named ones (one sensor:
//! a sample every 3 ms or so). A sample that takes longer than `--every` is said once, and
//! `--seconds` counts the unit's clock, not rows. Ctrl-C ends the run with what it has (the
//! table, the rows, the plot of the samples so far) and exit status 130.

mod plot;

use std::error::Error;
use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::sync::atomic::Ordering;

use mmu_firmware::registers::{
    FILTERED, RAW, SENSOR_FAULTS as STUCK, SLOT_COUNT, THRESHOLD_OFF, THRESHOLD_ON,
};
use mmu_firmware::unit::SensorId;
use mmu_protocol::{ErrorCode, ParamCode, Request, RequestCode};
use mmu_sim::{Decision, Operator, Personality, Printer, PrinterEvent, PrinterOptions};

use crate::printer_cli::console::Target;
use crate::printer_cli::serial::{FsensorSource, NoAnswerHint, SerialLink};
use crate::printer_cli::{CHOOSE_THE_UNIT, SimTargetArgs, ctrl_c_flag, parse_version, sim_link};
use crate::usage::{Interrupted, usage};

/// `mmu sensors` options.
#[derive(Debug, clap::Args)]
pub struct SensorsArgs {
    /// A real unit on this serial port (115200 8N1): a USB-serial adapter on USART1 (PB6/PB7; Pico: UART0, GP0/GP1),
    /// e.g. /dev/ttyUSB0 (not the NUCLEO's /dev/ttyACM0, the ST-LINK port).
    #[arg(long, value_name = "DEV", conflicts_with = "sim")]
    pub port: Option<String>,
    /// The in-process simulator (real time for the table; as fast as possible with --seconds
    /// and --csv or --plot, unless --time-scale).
    #[arg(long)]
    pub sim: bool,
    /// The simulated unit (--sim only).
    #[command(flatten)]
    pub sim_options: SimTargetArgs,
    /// Stream CSV: a header, then one row per sample, until Ctrl-C or --seconds.
    #[arg(long, conflicts_with = "plot")]
    pub csv: bool,
    /// Record --seconds of samples and draw them to this PNG: per sensor, raw and filtered
    /// readings against the thresholds.
    #[arg(long, value_name = "FILE.png", requires = "seconds")]
    pub plot: Option<PathBuf>,
    /// Stop after this many seconds (the unit's clock: virtual with --sim).
    #[arg(long, value_name = "N", value_parser = parse_seconds)]
    pub seconds: Option<f64>,
    /// Time between samples, ms. Reading all nine sensors takes about 19 ms over the wire; read
    /// fewer (--sensor) to sample faster.
    #[arg(long, value_name = "MS", default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..=60_000))]
    pub every: u64,
    /// Read only this sensor (repeatable): hub.filament, hub.tension, hub.cutter,
    /// slotK.filament, slotK.motion, slotK.tension (K from 0, those the hardware has), or its
    /// number. Fewer sensors, faster samples.
    #[arg(long = "sensor", value_name = "NAME")]
    pub sensors: Vec<String>,
    /// The unit firmware version to expect (3.0.2 for a unit set up for an MK3S).
    #[arg(long, value_name = "X.Y.Z", default_value = "3.0.3", value_parser = parse_version)]
    pub expect_version: (u8, u8, u8),
}

/// One sensor's readings at one time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading {
    /// The sensor's number (its diagnostic index).
    pub sensor: u8,
    /// The sensor.
    pub id: SensorId,
    /// Raw ADC sample, 0..=4095.
    pub raw: u16,
    /// After the unit's filter.
    pub filtered: u16,
    /// Stuck at a supply rail (the unit no longer believes it).
    pub stuck: bool,
}

/// All sensors at one time.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// The unit's clock since the first sample, ms.
    pub t_ms: u64,
    /// One per sensor read.
    pub readings: Vec<Reading>,
}

/// A sensor's thresholds; `None` for the sensors that have none (tension, cutter).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Thresholds {
    /// Present (or high) at or above this.
    pub on: u16,
    /// Absent (or low) at or below this.
    pub off: u16,
}

/// The sensor's name: `hub filament`, `slot 1 motion sensor`.
pub fn sensor_name(id: SensorId) -> String {
    match id {
        SensorId::HubFilament => "hub filament".to_string(),
        SensorId::HubTension => "hub tension".to_string(),
        SensorId::HubCutter => "hub cutter".to_string(),
        SensorId::SlotFilament(k) => format!("slot {k} filament"),
        SensorId::Motion(k) => format!("slot {k} motion sensor"),
        SensorId::LaneTension(k) => format!("slot {k} tension"),
    }
}

/// The sensors `names` pick out of those a unit has (`sensors`, by number): each a short name
/// (`slot1.motion`, as the registers name it) or a number; all of them for none.
fn select_sensors(names: &[String], sensors: &[(u8, SensorId)]) -> Result<Vec<(u8, SensorId)>, String> {
    if names.is_empty() {
        return Ok(sensors.to_vec());
    }
    let mut selected = Vec::new();
    for name in names {
        let wanted = name.trim().to_ascii_lowercase();
        let sensor = sensors
            .iter()
            .find(|(i, id)| id.to_string() == wanted || i.to_string() == wanted)
            .copied()
            .ok_or_else(|| {
                let known: Vec<String> = sensors.iter().map(|(i, id)| format!("{id} ({i})")).collect();
                format!(
                    "--sensor {name}: this unit has no such sensor; it has {} (by name or number)",
                    known.join(", ")
                )
            })?;
        if !selected.contains(&sensor) {
            selected.push(sensor);
        }
    }
    Ok(selected)
}

/// The sensor's CSV column prefix: `hub_filament`, `slot1_motion`.
fn column_name(id: SensorId) -> String {
    id.to_string().replace('.', "_")
}

/// A person's word for what a sensor reads, following the unit's hysteresis: `previous` is
/// the state shown before (the state only changes past a threshold).
fn state(
    id: SensorId,
    reading: &Reading,
    thresholds: Option<Thresholds>,
    previous: Option<bool>,
) -> (String, Option<bool>) {
    if reading.stuck {
        return ("STUCK AT A RAIL: check its wiring".to_string(), previous);
    }
    let Some(thresholds) = thresholds else {
        return (String::new(), None);
    };
    let on = if reading.filtered >= thresholds.on {
        true
    } else if reading.filtered <= thresholds.off {
        false
    } else {
        previous.unwrap_or(false)
    };
    // Of the motion sensors only a Hall wave has thresholds: its magnet's edges.
    let hall = matches!(id, SensorId::Motion(_));
    let word = match (hall, on) {
        (true, true) => "high (magnet)",
        (true, false) => "low",
        (false, true) => "filament",
        (false, false) => "no filament",
    };
    (word.to_string(), Some(on))
}

/// The person at the printer for a read-only session: sees nothing, never has to decide; only
/// a port that gives no answer is worth a word (on stderr: stdout may be CSV).
#[derive(Default)]
struct Silent {
    no_answer: NoAnswerHint,
}

impl<L: Target> Operator<L> for Silent {
    fn event(&mut self, link: &mut L, event: &PrinterEvent) {
        if let Some(hint) = self.no_answer.on_event(link, event) {
            eprintln!("mmu: {hint}");
        }
    }

    fn decide(&mut self, _link: &mut L, _request: Request, _error: ErrorCode) -> Decision {
        Decision::GiveUp
    }
}

/// Reads the sensors of a unit over a read-only printer connection.
struct Sampler<L: Target> {
    printer: Printer<L>,
    /// The person at the printer.
    silent: Silent,
    /// The sensors the unit's hardware has, by number.
    sensors: Vec<(u8, SensorId)>,
    /// The sensors read.
    selected: Vec<(u8, SensorId)>,
}

impl<L: Target> Sampler<L> {
    fn connect(link: L, version: (u8, u8, u8)) -> Result<Self, Box<dyn Error>> {
        let options = PrinterOptions {
            version,
            read_only: true,
            ..PrinterOptions::default()
        };
        let mut printer = Printer::new(link, options);
        let mut silent = Silent::default();
        printer
            .connect(&mut silent)
            .map_err(|error| crate::printer_cli::printer_failure(error, version))?;
        let mut sampler = Sampler {
            printer,
            silent,
            sensors: Vec::new(),
            selected: Vec::new(),
        };
        let slots = sampler
            .read(SLOT_COUNT)?
            .ok_or("the unit does not tell its number of slots (register 0x40): is it this firmware?")?;
        let slots = u8::try_from(slots)
            .ok()
            .filter(|&s| s <= 8)
            .ok_or("the unit claims too many slots")?;
        // The sensors this hardware has: those whose raw reading the unit answers.
        for index in 0..SensorId::count(usize::from(slots)) as u8 {
            if sampler.read(RAW + index)?.is_some() {
                let id = SensorId::from_index(usize::from(index), usize::from(slots));
                sampler.sensors.push((index, id));
            }
        }
        Ok(sampler)
    }

    fn read(&mut self, address: u8) -> Result<Option<u16>, Box<dyn Error>> {
        let answer = self
            .printer
            .request(&mut self.silent, Request::new(RequestCode::Read, address))
            .map_err(|error| error.to_string())?;
        Ok((answer.param == ParamCode::Accepted)
            .then_some(answer.param_value)
            .flatten())
    }

    /// The selected sensors' thresholds, in their order.
    fn thresholds(&mut self) -> Result<Vec<Option<Thresholds>>, Box<dyn Error>> {
        self.selected
            .clone()
            .into_iter()
            .map(|(i, _)| {
                let on = self.read(THRESHOLD_ON + i)?;
                let off = self.read(THRESHOLD_OFF + i)?;
                Ok(on.zip(off).map(|(on, off)| Thresholds { on, off }))
            })
            .collect()
    }

    fn sample(&mut self, t_ms: u64) -> Result<Sample, Box<dyn Error>> {
        let stuck = self.read(STUCK)?.unwrap_or(0);
        let mut readings = Vec::with_capacity(self.selected.len());
        for (i, id) in self.selected.clone() {
            let missing = || format!("the unit refused to read sensor {i} ({})", sensor_name(id));
            readings.push(Reading {
                sensor: i,
                id,
                raw: self.read(RAW + i)?.ok_or_else(missing)?,
                filtered: self.read(FILTERED + i)?.ok_or_else(missing)?,
                stuck: stuck & (1 << i) != 0,
            });
        }
        Ok(Sample { t_ms, readings })
    }

    fn now_ms(&self) -> u64 {
        self.printer.link().now_ms()
    }

    /// Let time pass until the unit's clock reads `until_ms`.
    fn wait_until(&mut self, until_ms: u64) -> Result<(), Box<dyn Error>> {
        while self.now_ms() < until_ms {
            let wait = until_ms - self.now_ms();
            self.printer.link_mut().receive(wait, &mut Vec::new())?;
        }
        Ok(())
    }
}

/// How the samples are shown.
enum Output {
    Table {
        live: bool,
        shown_lines: usize,
        states: Vec<Option<bool>>,
    },
    Csv,
    Plot(PathBuf),
}

/// Run `mmu sensors`.
pub fn run(args: &SensorsArgs) -> Result<(), Box<dyn Error>> {
    match (&args.port, args.sim) {
        (Some(port), false) => {
            let link = SerialLink::open(port, FsensorSource::Fixed(0))?;
            watch(Sampler::connect(link, args.expect_version)?, args)
        }
        (None, true) => {
            let mut sim = SimTargetArgs {
                ..args.sim_options.clone()
            };
            if sim.time_scale.is_none() && (args.seconds.is_none() || !(args.csv || args.plot.is_some())) {
                sim.time_scale = Some(1.0);
            }
            watch(
                Sampler::connect(sim_link(&sim, Personality::default())?, args.expect_version)?,
                args,
            )
        }
        _ => Err(usage(CHOOSE_THE_UNIT)),
    }
}

/// Sample until --seconds or Ctrl-C, showing each sample as asked.
fn watch<L: Target>(mut sampler: Sampler<L>, args: &SensorsArgs) -> Result<(), Box<dyn Error>> {
    sampler.selected = select_sensors(&args.sensors, &sampler.sensors).map_err(usage)?;
    if let Some(file) = &args.plot {
        check_plot_file(file)?;
    }
    let thresholds = sampler.thresholds()?;
    let stop = ctrl_c_flag()?;
    let mut output = match (&args.plot, args.csv) {
        (Some(file), _) => Output::Plot(file.clone()),
        (None, true) => Output::Csv,
        (None, false) => Output::Table {
            live: std::io::stdout().is_terminal(),
            shown_lines: 0,
            states: vec![None; sampler.selected.len()],
        },
    };
    let until = match args.seconds {
        Some(seconds) => format!("for {seconds} s"),
        None => "until Ctrl-C".to_string(),
    };
    eprintln!(
        "mmu sensors: reading {} sensor(s), a sample every {} ms, {until}",
        sampler.selected.len(),
        args.every
    );
    let mut out = std::io::stdout().lock();
    if let Output::Csv = output {
        writeln!(out, "{}", csv_header(&sampler.selected))?;
    }
    let start = sampler.now_ms();
    let end = args.seconds.map(|s| start + (s * 1000.0) as u64);
    let mut recorded = Vec::new();
    let mut last = None;
    let mut next = start;
    let mut said_slow = false;
    while !stop.load(Ordering::Relaxed) && end.is_none_or(|end| next <= end) {
        sampler.wait_until(next)?;
        let taken_at = sampler.now_ms();
        let sample = sampler.sample(taken_at - start)?;
        let done = sampler.now_ms();
        next += args.every;
        if done > next {
            // Reading took longer than --every: the next sample comes when this one is read.
            if !said_slow {
                let hint = if sampler.selected.len() > 1 {
                    " (--sensor NAME reads fewer, faster)"
                } else {
                    ""
                };
                eprintln!(
                    "mmu sensors: reading {} sensor(s) takes {} ms over this link, longer than --every {}: \
                     a sample every {} ms or so{hint}",
                    sampler.selected.len(),
                    done - taken_at,
                    args.every,
                    done - taken_at
                );
                said_slow = true;
            }
            next = done;
        }
        match &mut output {
            Output::Csv => {
                if writeln!(out, "{}", csv_row(&sample, &thresholds)).is_err() {
                    return Ok(()); // The reader went away (`| head`).
                }
                out.flush()?;
            }
            Output::Table {
                live: true,
                shown_lines,
                states,
            } => {
                if *shown_lines > 0 {
                    write!(out, "\x1b[{shown_lines}A")?;
                }
                let table = table(&sample, &thresholds, states, true);
                *shown_lines = table.lines().count();
                write!(out, "{table}")?;
                out.flush()?;
            }
            Output::Table { live: false, .. } => {}
            Output::Plot(_) => recorded.push(sample.clone()),
        }
        last = Some(sample);
    }
    let samples = match &output {
        Output::Plot(_) => recorded.len(),
        _ => usize::from(last.is_some()),
    };
    match output {
        Output::Table {
            live: false,
            mut states,
            ..
        } => {
            if let Some(sample) = &last {
                write!(out, "{}", table(sample, &thresholds, &mut states, false))?;
            }
        }
        Output::Plot(file) => {
            plot::draw(&file, &recorded, &thresholds)?;
            writeln!(
                out,
                "{} samples of {} sensors drawn to {}",
                recorded.len(),
                sampler.selected.len(),
                file.display()
            )?;
        }
        _ => {}
    }
    if stop.load(Ordering::Relaxed) {
        out.flush()?;
        let what = if samples > 0 {
            "what was read is shown above"
        } else {
            "no sample was read"
        };
        return Err(Box::new(Interrupted(format!("stopped by Ctrl-C: {what}"))));
    }
    Ok(())
}

/// A plot goes to a PNG file that can be written: said before recording, not after.
fn check_plot_file(file: &std::path::Path) -> Result<(), Box<dyn Error>> {
    let png = file
        .extension()
        .is_some_and(|ext| ext.eq_ignore_ascii_case("png"));
    if !png {
        return Err(usage(format!(
            "--plot {}: the plot is a PNG image: give a file name ending in .png",
            file.display()
        )));
    }
    std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(false)
        .open(file)
        .map_err(|error| {
            usage(format!(
                "--plot {}: cannot write there ({error}); nothing was recorded",
                file.display()
            ))
        })?;
    Ok(())
}

fn csv_header(sensors: &[(u8, SensorId)]) -> String {
    let mut columns = vec!["t_ms".to_string()];
    for &(_, id) in sensors {
        let name = column_name(id);
        for field in ["raw", "filtered", "on", "off", "stuck"] {
            columns.push(format!("{name}_{field}"));
        }
    }
    columns.join(",")
}

/// A CSV row; thresholds a sensor lacks are empty.
fn csv_row(sample: &Sample, thresholds: &[Option<Thresholds>]) -> String {
    let mut row = vec![sample.t_ms.to_string()];
    for (reading, limits) in sample.readings.iter().zip(thresholds) {
        row.push(reading.raw.to_string());
        row.push(reading.filtered.to_string());
        row.push(limits.map_or(String::new(), |t| t.on.to_string()));
        row.push(limits.map_or(String::new(), |t| t.off.to_string()));
        row.push(u8::from(reading.stuck).to_string());
    }
    row.join(",")
}

/// The table: a header and one line per sensor; `live` lines end in "clear to the end of the
/// line", for a terminal where the table is redrawn in place.
fn table(
    sample: &Sample,
    thresholds: &[Option<Thresholds>],
    states: &mut [Option<bool>],
    live: bool,
) -> String {
    let eol = if live { "\x1b[K\n" } else { "\n" };
    let mut text = format!(
        "t = {:>8.1} s{}{eol}{:<3} {:<21} {:>5} {:>8} {:>5} {:>5}  state{eol}",
        sample.t_ms as f64 / 1000.0,
        if live { "   (Ctrl-C stops)" } else { "" },
        "#",
        "sensor",
        "raw",
        "filtered",
        "on",
        "off"
    );
    for (position, (reading, limits)) in sample.readings.iter().zip(thresholds).enumerate() {
        let i = reading.sensor;
        let previous = states.get(position).copied().flatten();
        let (word, now) = state(reading.id, reading, *limits, previous);
        if let Some(slot) = states.get_mut(position) {
            *slot = now;
        }
        let (on, off) = limits.map_or((String::from("-"), String::from("-")), |t| {
            (t.on.to_string(), t.off.to_string())
        });
        text.push_str(&format!(
            "{i:<3} {:<21} {:>5} {:>8} {on:>5} {off:>5}  {word}{eol}",
            sensor_name(reading.id),
            reading.raw,
            reading.filtered
        ));
    }
    text
}

fn parse_seconds(text: &str) -> Result<f64, String> {
    text.parse::<f64>()
        .ok()
        .filter(|s| s.is_finite() && *s > 0.0 && *s <= 86_400.0)
        .ok_or_else(|| format!("{text:?} is not a number of seconds (above 0, at most a day)"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sensors of a 3-slot unit on the thesis build, as the sampler finds them.
    fn thesis_sensors() -> Vec<(u8, SensorId)> {
        (0..9)
            .map(|i| (i, SensorId::from_index(usize::from(i), 3)))
            .collect()
    }

    #[test]
    fn names_follow_the_register_map() {
        let names: Vec<String> = thesis_sensors()
            .into_iter()
            .map(|(_, id)| sensor_name(id))
            .collect();
        assert_eq!(
            names,
            [
                "hub filament",
                "hub tension",
                "hub cutter",
                "slot 0 filament",
                "slot 0 motion sensor",
                "slot 1 filament",
                "slot 1 motion sensor",
                "slot 2 filament",
                "slot 2 motion sensor"
            ]
        );
        assert_eq!(column_name(SensorId::Motion(2)), "slot2_motion");
        assert_eq!(column_name(SensorId::from_index(12, 4)), "slot1_tension");
    }

    #[test]
    fn the_state_follows_the_hysteresis() {
        let limits = Some(Thresholds { on: 2600, off: 2400 });
        let at = |filtered| Reading {
            sensor: 0,
            id: SensorId::HubFilament,
            raw: filtered,
            filtered,
            stuck: false,
        };
        let hub = SensorId::HubFilament;
        assert_eq!(state(hub, &at(2700), limits, None).0, "filament");
        assert_eq!(state(hub, &at(2500), limits, Some(true)).0, "filament");
        assert_eq!(state(hub, &at(2500), limits, Some(false)).0, "no filament");
        assert_eq!(state(hub, &at(2300), limits, Some(true)).0, "no filament");
        assert_eq!(
            state(SensorId::Motion(0), &at(2700), limits, None).0,
            "high (magnet)"
        );
        assert_eq!(state(SensorId::HubTension, &at(2700), None, None).0, "");
        let stuck = Reading { stuck: true, ..at(0) };
        assert!(state(hub, &stuck, limits, None).0.contains("wiring"));
    }

    #[test]
    fn sensors_are_picked_by_name_or_number() {
        let sensors = thesis_sensors();
        assert_eq!(select_sensors(&[], &sensors), Ok(sensors.clone()));
        let names = |list: &[&str]| list.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert_eq!(
            select_sensors(&names(&["slot0.motion"]), &sensors),
            Ok(vec![(4, SensorId::Motion(0))])
        );
        assert_eq!(
            select_sensors(&names(&["8", "HUB.filament", "8"]), &sensors),
            Ok(vec![(8, SensorId::Motion(2)), (0, SensorId::HubFilament)])
        );
        let error =
            select_sensors(&names(&["slot3.motion"]), &sensors).expect_err("a 3-slot unit has no slot 3");
        assert!(error.contains("slot2.motion"), "{error}");
        // A unit without hub sensors has none to pick.
        let bmcu: Vec<(u8, SensorId)> = (3..15)
            .map(|i| (i, SensorId::from_index(usize::from(i), 4)))
            .collect();
        let error = select_sensors(&names(&["hub.filament"]), &bmcu).expect_err("no hub sensor");
        assert!(error.contains("slot3.tension"), "{error}");
    }
}
