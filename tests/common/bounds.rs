//! The App under arbitrary input and the bounds it must keep, shared by the proptest
//! (`tests/properties.rs`) and the App fuzz target (`fuzz/fuzz_targets/app.rs`, which includes
//! this file by path).

use mmu_firmware::follower;
use mmu_firmware::runner::Status;
use mmu_firmware::{App, Config, Direction, Instant, MotorCommand, Samples};
use mmu_protocol::ResponseDecoder;

/// The longest any single phase may drive with the default configuration: the slow search for
/// the printer's sensor after Retry of `8003`, over the whole Bowden tube, (360 + 90) mm at
/// 20 mm/s, twice over, plus 1 s of slack.
pub const LONGEST_PHASE_MS: u64 = 450 * 2000 / 20 + 1000;

/// Follows the App's motor commands step by step.
pub struct Watch<const N: usize> {
    /// Per slot: since when it has been driven by the same phase of the same operation.
    driven_since: [Option<(u64, String)>; N],
    /// Per slot: since when the tension follower has driven it.
    followed_since: [Option<u64>; N],
}

impl<const N: usize> Default for Watch<N> {
    fn default() -> Self {
        Watch {
            driven_since: core::array::from_fn(|_| None),
            followed_since: [None; N],
        }
    }
}

impl<const N: usize> Watch<N> {
    /// Never two slots fed towards the hub at once; no phase drives a motor beyond
    /// [`LONGEST_PHASE_MS`]; no motor moves while the unit holds an error; the tension follower
    /// never assists longer than its still time without a revolution. Says what went wrong.
    pub fn check(&mut self, app: &App<N>, now: u64, motors: &[MotorCommand; N]) -> Result<(), String> {
        let forward = motors
            .iter()
            .filter(|m| matches!(m, MotorCommand::Drive { direction: Direction::Forward, duty } if duty.permille() > 0))
            .count();
        if forward > 1 {
            return Err(format!("two slots fed towards the hub at once: {motors:?}"));
        }
        if matches!(app.operation().status(), Status::Failed(_)) && motors.iter().any(|m| m.is_driving()) {
            return Err(format!(
                "a motor driven while the unit holds an error: {motors:?}"
            ));
        }
        let phase = format!("{:?}/{:?}", app.operation().request, app.operation().phase());
        for (slot, motor) in motors.iter().enumerate() {
            let by_phase = app.operation().driving_slot() == Some(slot) && motor.is_driving();
            let entry = &mut self.driven_since[slot];
            match (by_phase, entry.as_ref()) {
                (true, Some((since, running))) if *running == phase => {
                    if now - since > LONGEST_PHASE_MS {
                        return Err(format!("slot {slot} driven {} ms in {phase}", now - since));
                    }
                }
                (true, _) => *entry = Some((now, phase.clone())),
                (false, _) => *entry = None,
            }
            // The follower: driven, but never longer than its still time without a revolution.
            let follows = !by_phase && motor.is_driving();
            let followed = &mut self.followed_since[slot];
            *followed = follows.then(|| followed.unwrap_or(now));
            if let (Some(since), Some(feeder)) = (*followed, app.unit().feeders.get(slot)) {
                let still_since = since.max(feeder.motion.last_mark().as_millis());
                if now - still_since > follower::STILL_MS + 1 {
                    return Err(format!(
                        "slot {slot} assisted {} ms without a revolution",
                        now - still_since
                    ));
                }
            }
        }
        Ok(())
    }
}

/// An App stepped in virtual time, checked after every step.
pub struct Bench<const N: usize> {
    app: App<N>,
    watch: Watch<N>,
    now: u64,
}

impl<const N: usize> Default for Bench<N> {
    fn default() -> Self {
        Bench {
            app: App::new(Config::default()),
            watch: Watch::default(),
            now: 0,
        }
    }
}

impl<const N: usize> Bench<N> {
    /// Virtual time, ms.
    pub fn now(&self) -> u64 {
        self.now
    }

    /// One step with the printer's bytes `rx` (a reset request restarts the App), then
    /// `hold_ms` steps (at least a line silence) with nothing sent, all with `samples`; then a `Q0`
    /// after a newline must get exactly one well-formed answer (the decoder resynchronises there),
    /// or none while the start-up check still runs. Says what went wrong.
    pub fn feed(&mut self, rx: &[u8], samples: &Samples<N>, hold_ms: u64) -> Result<(), String> {
        let out = self.app.step(Instant::from_millis(self.now), samples, rx);
        self.watch.check(&self.app, self.now, &out.motors)?;
        if out.action.is_some() {
            self.app = App::new(Config::default());
            self.watch = Watch::default();
        }
        // At least a silence: after garbage only a silent line starts a new frame.
        for _ in 0..hold_ms.max(mmu_protocol::SILENCE_MS.into()) {
            self.now += 1;
            let out = self.app.step(Instant::from_millis(self.now), samples, &[]);
            self.watch.check(&self.app, self.now, &out.motors)?;
        }
        let listening = self.app.is_listening();
        let answer = self
            .app
            .step(Instant::from_millis(self.now), samples, b"\nQ0*ea\n");
        let mut decoder = ResponseDecoder::new();
        let frames: Vec<_> = answer.tx.iter().filter_map(|&b| decoder.feed(b)).collect();
        match (listening, frames.as_slice()) {
            (true, [Ok(_)]) | (false, []) => Ok(()),
            _ => Err(format!("Q0 got {frames:?} (listening: {listening})")),
        }
    }
}
