//! The motor test of one slot, for the first power-on: does the motor turn both ways, and does its
//! motion sensor (a Hall wave, an encoder, an angle sensor) count it?
//!
//! The unit has no jog command, so the test asks for the one motion that is short, bounded and
//! supervised and needs no printer: a preload (`L<slot>`), which feeds the slot's filament forward
//! until the hub sensor sees it (at most the preload bound, register 0x46) and pulls it back to
//! its park position. While the unit runs it, the test reads the slot's odometry (0xb0+k: the
//! unit's count of motor revolutions, in mm), its motor Hall sensor's raw reading (0x64+2k) and,
//! every tenth of a second, the command's state (`Q0`). Then it says how far the filament went
//! each way, how the Hall reading swung against its thresholds, and what to check when something
//! is off. A slot without filament at its sensor is refused: the unit would not drive it.

use mmu_protocol::{ErrorCode, ParamCode, ProgressCode, Request, RequestCode};

use crate::explain::error_meaning;

use super::Bench;

/// How often the command's state is asked while the motor runs, ms (the printer asks every 1000).
const STATE_EVERY_MS: u64 = 100;
/// The longest a preload may take before the test stops waiting, ms of the unit's clock.
const LONGEST_MS: u64 = 60_000;

/// What the test saw.
#[derive(Debug, Clone, PartialEq)]
pub struct MotorReport {
    /// The slot tested.
    pub slot: u8,
    /// Filament moved towards the hub, mm (odometry).
    pub forward_mm: i32,
    /// Filament moved back, mm (odometry).
    pub back_mm: i32,
    /// The motion sensor's lowest and highest raw reading.
    pub hall_range: (u16, u16),
    /// Its thresholds, on and off: a Hall wave's; `None` for a counting sensor (an encoder's
    /// count, an angle), which has none.
    pub hall_thresholds: Option<(u16, u16)>,
    /// Times the sampled reading went from below "off" to above "on".
    pub hall_rises: u32,
    /// Readings taken.
    pub samples: usize,
    /// How long the preload took, ms.
    pub duration_ms: u64,
    /// The error the unit stopped on, if any: it then waits for Retry.
    pub error: Option<ErrorCode>,
}

impl MotorReport {
    /// Whether the motor turned both ways and the Hall sensor counted it: the unit finished the
    /// preload. It feeds until the hub sensor sees the tip and pulls back until it clears, and it
    /// stops with a stall error on a motor driven without revolutions: a finished preload proves
    /// both, whatever the PC's readings caught.
    pub fn passed(&self) -> bool {
        self.error.is_none()
    }

    /// The report, line by line, with what to check.
    pub fn lines(&self) -> Vec<String> {
        let (low, high) = self.hall_range;
        let sensor = match self.hall_thresholds {
            Some((on, off)) => format!(
                "motor Hall sensor: raw {low} to {high} over {} readings, thresholds off {off} / on {on}{}",
                self.samples,
                if low <= off && high >= on {
                    ": it swings across both"
                } else {
                    ": it does NOT swing across both"
                }
            ),
            None => format!(
                "motion sensor (a count or an angle): raw {low} to {high} over {} readings",
                self.samples
            ),
        };
        let mut lines = vec![
            format!(
                "slot {}: forward {} mm, back {} mm in {:.1} s (the unit's odometry: turns of its motion sensor × mm per turn)",
                self.slot,
                self.forward_mm,
                self.back_mm,
                self.duration_ms as f64 / 1000.0
            ),
            sensor,
        ];
        if let Some(error) = self.error {
            lines.push(format!(
                "the unit stopped on {}: it waits; fix the cause, then `retry` (or the printer's Retry)",
                error_meaning(error)
            ));
        }
        lines.extend(self.advice());
        lines
    }

    /// What to check, from what was seen.
    fn advice(&self) -> Vec<String> {
        let (low, high) = self.hall_range;
        let mut advice = Vec::new();
        if self.passed() {
            if self.forward_mm <= 0 || self.back_mm <= 0 {
                advice.push(
                    "(the readings missed part of the motion, which was quicker than the PC reads; the unit's own \
                     check is what passed)"
                        .to_string(),
                );
            }
            advice.push(format!(
                "motor test passed: slot {}'s motor turns both ways and its motion sensor counts it",
                self.slot
            ));
            return advice;
        }
        if self.forward_mm <= 0 {
            advice.push(
                "no motion was counted forward: the motor did not turn (its wires, its bridge, the motor supply) \
                 or its motion sensor does not see it (the Hall's magnet, the encoder's wires, the angle sensor's \
                 magnet)"
                    .to_string(),
            );
        }
        if let Some((on, off)) = self.hall_thresholds
            && !(low <= off && high >= on)
        {
            advice.push(format!(
                "the Hall reading stayed between {low} and {high}: bring the magnet closer to the sensor, or put the \
                 thresholds inside that swing (on above off, e.g. `set threshold_on.slot{k}.motion ...`); a motor at full \
                 speed turns faster than the PC can sample, so a narrow range here can also be sampling",
                k = self.slot
            ));
        }
        if self.forward_mm > 0 && self.error == Some(ErrorCode::FINDA_DIDNT_SWITCH_ON) {
            advice.push(
                "the motor turned but the hub sensor never saw the tip: does the drive gear grip the filament, and does \
                 the motor turn towards the hub? (if not, swap its two wires)"
                    .to_string(),
            );
        }
        advice
    }
}

/// Run the motor test on `slot`. See the [module documentation](self).
pub fn run(bench: &mut Bench, slot: u8) -> Result<MotorReport, String> {
    let slots = bench.slots();
    if slot >= slots {
        return Err(format!(
            "the unit has no slot {slot}: it has {slots} (0-{})",
            slots.saturating_sub(1)
        ));
    }
    bench.refuse_if_waiting(&Request::new(RequestCode::Load, slot))?;
    for other in 0..slots {
        if matches!(bench.read(0xb8 + other)?, 2 | 4 | 8) {
            return Err(format!(
                "slot {other}'s filament is past its park position: unload first (`unload`); \
                 the motor test feeds slot {slot} to the hub and back"
            ));
        }
    }
    let sensor = 3 + 2 * slot;
    let filtered = bench.read(0x70 + sensor)?;
    let present_at = bench.read(0x90 + sensor)?;
    if filtered < present_at {
        return Err(format!(
            "slot {slot} has no filament at its sensor (it reads {filtered}, filament is {present_at} or more): \
             push a filament in past the drive gear first; the unit does not drive an empty slot"
        ));
    }
    let hall = 4 + 2 * slot;
    // Only a Hall wave has thresholds (an older firmware without register 0x8d has one).
    let hall_wave = bench
        .read(mmu_firmware::registers::HARDWARE)
        .map_or(true, |code| code & 0b11 == 0);
    let thresholds = if hall_wave {
        Some((bench.read(0x90 + hall)?, bench.read(0xa0 + hall)?))
    } else {
        None
    };
    // Odometry from where the test starts, mm: the register wraps at 16 bits (and the unit's
    // odometry at 32), so positions are wrapping differences from the first reading.
    let start_raw = bench.read(0xb0 + slot)?;
    let odometry = |bench: &mut Bench| -> Result<i32, String> {
        Ok(i32::from(bench.read(0xb0 + slot)?.wrapping_sub(start_raw) as i16))
    };

    bench.say(&format!(
        "motor test of slot {slot}: a preload (L{slot}) feeds its filament to the hub sensor and back to park"
    ));
    let start_odometry = odometry(bench)?;
    let answer = bench.request(Request::new(RequestCode::Load, slot))?;
    if answer.param != ParamCode::Accepted {
        return Err(format!(
            "the unit refused the preload L{slot} ({answer:?}): is it busy?"
        ));
    }
    let started = bench.now_ms();
    let mut next_state = started;
    let (mut low, mut high) = (u16::MAX, 0u16);
    let mut furthest = start_odometry;
    let mut last;
    let mut rises = 0u32;
    let mut above: Option<bool> = None;
    let mut samples = 0usize;
    let mut seen_progress: Option<ProgressCode> = None;
    let error = loop {
        let reading = bench.read(0x60 + hall)?;
        samples += 1;
        low = low.min(reading);
        high = high.max(reading);
        let now_above = match thresholds {
            Some((on, _)) if reading >= on => Some(true),
            Some((_, off)) if reading <= off => Some(false),
            _ => above,
        };
        if above == Some(false) && now_above == Some(true) {
            rises += 1;
        }
        above = now_above;
        last = odometry(bench)?;
        furthest = furthest.max(last);
        let now = bench.now_ms();
        if now >= next_state {
            next_state = now + STATE_EVERY_MS;
            let state = bench.request(Request::new(RequestCode::Query, 0))?;
            match state.param {
                ParamCode::Finished => break None,
                ParamCode::Error => break Some(ErrorCode(state.param_value.unwrap_or(0))),
                ParamCode::Processing => {
                    let progress = ProgressCode(state.param_value.unwrap_or(0) as u8);
                    if seen_progress != Some(progress) {
                        seen_progress = Some(progress);
                        bench.say(&format!("  {:.1} s  {progress}", (now - started) as f64 / 1000.0));
                    }
                }
                _ => {}
            }
        }
        if now - started > LONGEST_MS {
            return Err(format!(
                "the preload did not end within {} s: `status` tells what the unit does",
                LONGEST_MS / 1000
            ));
        }
    };
    let report = MotorReport {
        slot,
        forward_mm: furthest - start_odometry,
        back_mm: furthest - last,
        hall_range: (low, high),
        hall_thresholds: thresholds,
        hall_rises: rises,
        samples,
        duration_ms: bench.now_ms() - started,
        error,
    };
    Ok(report)
}
