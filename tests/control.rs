//! The control loop's policy, as the board runs it: button debounce, the watchdog rule, the
//! statistics period and the order of a reset.

use std::cell::RefCell;

use embassy_futures::block_on;
use mmu_firmware::control::{self, ControlLoop, Debounce, ResetBoard, Tick, feeds_watchdog};
use mmu_firmware::uart::{MemoryRing, ReceiveRing};
use mmu_firmware::{App, BoardAction, Instant, Samples};

/// The printer's bytes as the board receives them.
type Received = ReceiveRing<MemoryRing<64>, 64>;

fn received() -> Received {
    ReceiveRing::new(MemoryRing::new())
}

fn at(ms: u64) -> Instant {
    Instant::from_millis(ms)
}

#[test]
fn a_press_counts_once_after_it_held_for_the_debounce_time() {
    let mut button = Debounce::new(at(0));
    // Contact bounce: down, up, down within a few ms never counts.
    assert!(!button.pressed(true, at(1)));
    assert!(!button.pressed(false, at(3)));
    assert!(!button.pressed(true, at(5)));
    assert!(!button.pressed(true, at(24)));
    assert!(button.pressed(true, at(25)));
    // Held: no second press; released and pressed again: one more.
    assert!(!button.pressed(true, at(200)));
    assert!(!button.pressed(false, at(210)));
    assert!(!button.pressed(false, at(240)));
    assert!(!button.pressed(true, at(250)));
    assert!(button.pressed(true, at(270)));
}

#[test]
fn only_a_step_on_time_with_fresh_samples_feeds_the_watchdog() {
    assert!(feeds_watchdog(0, 0));
    assert!(feeds_watchdog(control::ON_TIME_US, control::MAX_SAMPLE_AGE_US));
    assert!(!feeds_watchdog(control::ON_TIME_US + 1, 0));
    assert!(!feeds_watchdog(0, control::MAX_SAMPLE_AGE_US + 1));
}

/// Mid-scale readings: every sensor healthy, no filament anywhere.
const SAMPLES: Samples<3> = Samples::uniform(2048);

fn tick(now: u64, lateness_us: u64) -> Tick<'static, 3> {
    Tick {
        now: at(now),
        lateness_us,
        sample_age_us: 0,
        samples: &SAMPLES,
        button_down: false,
    }
}

#[test]
fn the_loop_counts_late_steps_and_reports_once_a_period() {
    let mut control = ControlLoop::new(App::<3>::default(), at(0));
    let mut reports = Vec::new();
    let mut received = received();
    for ms in 0..=control::STATS_PERIOD_MS {
        let late = if ms == 10 { 3_000 } else { 0 };
        let step = control.step(&tick(ms, late), &mut received);
        assert_eq!(step.feed_watchdog, late == 0, "step {ms}");
        reports.extend(step.report);
    }
    let [report] = reports.as_slice() else {
        panic!("one report per period, got {reports:?}");
    };
    assert_eq!((report.late, report.unfed, report.max_lateness_us), (1, 1, 3_000));
    assert!(report.troubled());
}

#[test]
fn a_reset_request_does_not_feed_the_watchdog() {
    let mut control = ControlLoop::new(App::<3>::default(), at(0));
    // The unit hears nothing during its start-up check (at most about a second); then the
    // line has been quiet: the request is a whole frame.
    let mut received = received();
    for ms in 1..1500 {
        control.step(&tick(ms, 0), &mut received);
    }
    received.source_mut().receive(b"X0*4c\n");
    let step = control.step(&tick(1500, 0), &mut received);
    assert_eq!(step.out.action, Some(BoardAction::Reset));
    assert!(!step.feed_watchdog);
}

/// Records what a reset did, in order.
#[derive(Default)]
struct Recorder(RefCell<Vec<String>>);

impl ResetBoard for &Recorder {
    fn stop_motors(&mut self) {
        self.0.borrow_mut().push("motors off".into());
    }
    async fn flush(&mut self) {
        self.0.borrow_mut().push("flush".into());
    }
    async fn persist(&mut self, action: BoardAction) {
        self.0.borrow_mut().push(format!("persist {action:?}"));
    }
    fn restart(&mut self) {
        self.0.borrow_mut().push("restart".into());
    }
}

#[test]
fn a_reset_stops_the_motors_first_and_saves_before_restarting() {
    for action in [BoardAction::Reset, BoardAction::EraseAndReset] {
        let recorder = Recorder::default();
        block_on(control::reset(&mut &recorder, action));
        assert_eq!(
            recorder.0.into_inner(),
            ["motors off", "flush", &format!("persist {action:?}"), "restart"]
        );
    }
}

#[test]
fn responses_the_board_could_not_send_are_counted_in_register_0x51() {
    let mut control = ControlLoop::new(App::<3>::default(), at(0));
    assert_eq!(control.app().read_register(0x51), Some(0));
    control.tx_dropped();
    control.tx_dropped();
    assert_eq!(control.app().read_register(0x51), Some(2));
}
