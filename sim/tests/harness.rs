//! The simulator's own duties, driven byte by byte: power loss, the printer's unload before a
//! command, scheduled faults and the event stream.

use mmu_protocol::{ParamCode, Request, RequestCode, Response, ResponseDecoder};
use mmu_sim::{EventKind, ScheduledFault, Sim, SimFault, SimOptions};

/// A bare client: sends frames, steps the simulator, collects the answers.
struct Wire {
    sim: Sim,
    decoder: ResponseDecoder,
    reported: u8,
}

impl Wire {
    fn new() -> Self {
        Wire {
            sim: Sim::new(SimOptions::default()).unwrap(),
            decoder: ResponseDecoder::new(),
            reported: 0,
        }
    }

    /// Send `request` and step until an answer comes, at most `max_ms`; returns it and when.
    fn ask(&mut self, request: Request, max_ms: u64) -> Option<(Response, u64)> {
        let mut rx = request.encode().as_bytes().to_vec();
        for _ in 0..max_ms {
            let mut tx = Vec::new();
            self.sim.step(&std::mem::take(&mut rx), &mut tx);
            for byte in tx {
                if let Some(Ok(answer)) = self.decoder.feed(byte) {
                    return Some((answer, self.sim.now_ms()));
                }
            }
        }
        None
    }

    /// The version check of a printer that wants MMU 3.0.3 (Buddy 6.4, whose mechanics the
    /// simulator plays): `S2` asked again until it answers 3, then `S3`.
    fn connect_as_3_0_3(&mut self) {
        let s2 = Request::new(RequestCode::Version, 2);
        for _ in 0..5 {
            if self.ask(s2, 10).and_then(|(a, _)| a.param_value) == Some(3) {
                break;
            }
        }
        self.ask(Request::new(RequestCode::Version, 3), 10).unwrap();
    }

    fn idle(&mut self, ms: u64) {
        for _ in 0..ms {
            self.sim.step(&[], &mut Vec::new());
        }
    }

    fn query(&mut self) -> Response {
        self.ask(Request::new(RequestCode::Query, 0), 10).unwrap().0
    }

    /// Run a command to its end the way the printer would.
    fn command(&mut self, request: Request) -> Response {
        assert_eq!(self.ask(request, 3000).unwrap().0.param, ParamCode::Accepted);
        self.follow()
    }

    /// Follow the command in progress to its end, reporting the printer's filament sensor.
    fn follow(&mut self) -> Response {
        for _ in 0..200 {
            self.idle(200);
            let state = self.sim.model().fsensor_state();
            if state != self.reported {
                self.ask(Request::new(RequestCode::FilamentSensor, state), 10)
                    .unwrap();
                self.reported = state;
            }
            let answer = self.query();
            if answer.param != ParamCode::Processing {
                return answer;
            }
        }
        panic!("the command did not end");
    }
}

#[test]
fn power_loss_silences_the_unit_then_it_boots_fresh() {
    let mut wire = Wire::new();
    wire.idle(300);
    assert_eq!(wire.query().param, ParamCode::Finished);
    wire.sim.inject(SimFault::PowerLoss { off_ms: 400 });
    assert!(!wire.sim.is_powered());
    assert_eq!(wire.ask(Request::new(RequestCode::Query, 0), 350), None);
    wire.idle(100);
    assert!(wire.sim.is_powered());
    // A fresh unit (its line quiet since it booted) answers for its start-up check, X0.
    let (answer, _) = wire.ask(Request::new(RequestCode::Query, 0), 10).unwrap();
    assert_eq!(answer.code, RequestCode::Reset);
    let power: Vec<bool> = wire
        .sim
        .take_events()
        .into_iter()
        .filter_map(|e| match e.what {
            EventKind::Power { on } => Some(on),
            _ => None,
        })
        .collect();
    assert_eq!(power, [false, true]);
}

#[test]
fn the_printer_unloads_its_extruder_before_the_unit_hears_the_unload() {
    let mut wire = Wire::new();
    wire.idle(300);
    wire.connect_as_3_0_3();
    let done = wire.command(Request::new(RequestCode::Tool, 1));
    assert_eq!(done.param, ParamCode::Finished);
    let gears = wire.sim.model().config().extruder_gears_mm;
    assert!(
        wire.sim.model().tip_mm(1).unwrap() >= gears,
        "loaded into the gears"
    );
    // The printer loads on into its nozzle (60 mm at 15 mm/s).
    wire.idle(4500);
    assert_eq!(wire.sim.model().fsensor_state(), 2);

    let sent = wire.sim.now_ms();
    let (answer, answered) = wire.ask(Request::new(RequestCode::Unload, 0), 3000).unwrap();
    assert_eq!(
        (answer.code, answer.param),
        (RequestCode::Unload, ParamCode::Accepted)
    );
    let delay = answered - sent;
    assert!((900..1500).contains(&delay), "answered after {delay} ms");
    assert!(
        wire.sim.model().tip_mm(1).unwrap() < gears,
        "out of the gears first"
    );
    assert!(wire.sim.take_events().iter().any(|e| matches!(
        e.what,
        EventKind::Extruder {
            action: "ramming",
            ..
        }
    )));
    assert_eq!(wire.follow().param, ParamCode::Finished);
}

#[test]
fn scheduled_faults_come_and_go_on_time_and_are_reported() {
    let mut wire = Wire::new();
    wire.sim
        .schedule("jam:1@100-200".parse::<ScheduledFault>().unwrap());
    wire.sim
        .schedule("uart-drop:1@150-250".parse::<ScheduledFault>().unwrap());
    wire.idle(120);
    assert_eq!(wire.sim.active_faults().len(), 1);
    wire.idle(50);
    assert_eq!(wire.sim.active_faults().len(), 2);
    // Every byte is lost while uart-drop:1 holds.
    assert_eq!(wire.ask(Request::new(RequestCode::Query, 0), 20), None);
    wire.idle(100);
    assert!(wire.sim.active_faults().is_empty());
    let lines: Vec<String> = wire
        .sim
        .take_events()
        .iter()
        .filter(|e| matches!(e.what, EventKind::Fault { .. }))
        .map(|e| e.to_json())
        .collect();
    assert_eq!(
        lines,
        [
            r#"{"t_ms":100,"kind":"fault","action":"inject","fault":"jam:1"}"#,
            r#"{"t_ms":150,"kind":"fault","action":"inject","fault":"uart-drop:1"}"#,
            r#"{"t_ms":200,"kind":"fault","action":"clear","fault":"jam:1"}"#,
            r#"{"t_ms":250,"kind":"fault","action":"clear","fault":"uart-drop"}"#,
        ]
    );
}

#[test]
fn a_tool_change_reports_the_printer_sensor_and_slot_motion() {
    let mut wire = Wire::new();
    wire.idle(300);
    wire.command(Request::new(RequestCode::Tool, 0));
    let events = wire.sim.take_events();
    let states: Vec<u8> = events
        .iter()
        .filter_map(|e| match e.what {
            EventKind::Fsensor { state } => Some(state),
            _ => None,
        })
        .collect();
    assert_eq!(states.first(), Some(&1), "{states:?}");
    let slot0 = events
        .iter()
        .filter(|e| matches!(e.what, EventKind::Slot { slot: 0, .. }))
        .count();
    assert!(slot0 > 20, "slot 0 moved about 380 mm: {slot0} reports");
    assert!(events.windows(2).all(|w| w[0].t_ms <= w[1].t_ms));
}

#[test]
fn every_change_of_a_motor_command_is_an_event() {
    let mut wire = Wire::new();
    wire.idle(300);
    wire.command(Request::new(RequestCode::Tool, 1));
    wire.idle(500);
    let motor: Vec<String> = wire
        .sim
        .take_events()
        .iter()
        .filter(|e| matches!(e.what, EventKind::Motor { .. }))
        .map(|e| e.to_json())
        .collect();
    let first = motor.first().expect("the tool change drove a motor");
    assert!(
        first.contains(r#""kind":"motor","slot":1,"state":"forward","duty":"#),
        "{first}"
    );
    assert!(
        motor.iter().all(|line| line.contains(r#""slot":1"#)),
        "only slot 1 moved"
    );
    let last = motor.last().unwrap();
    assert!(
        last.ends_with(r#""state":"coast","duty":0}"#),
        "it rests at the end: {last}"
    );
}
