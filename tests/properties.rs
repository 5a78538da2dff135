//! Properties of the App under arbitrary input: random requests, garbage bytes and sensor
//! values, and random commands and faults against the physical model.

mod common;

use common::Rig;
use common::bounds::Bench;
use mmu_firmware::runner::Status;
use mmu_firmware::{HubSamples, Samples, SlotSamples};
use mmu_model::{Fault, Rail, SensorId};
use mmu_protocol::{Request, RequestCode};
use proptest::prelude::*;

fn request() -> impl Strategy<Value = Request> {
    (0..RequestCode::ALL.len(), 0u8..8, any::<u16>()).prop_map(|(code, value, value2)| {
        let code = RequestCode::ALL[code];
        if code == RequestCode::Write {
            Request::write(value.wrapping_mul(9), value2)
        } else {
            Request::new(code, value)
        }
    })
}

/// What the printer side sends in one step.
#[derive(Debug, Clone)]
enum Input {
    Nothing,
    Frame(Request),
    Garbage(Vec<u8>),
}

fn input() -> impl Strategy<Value = Input> {
    prop_oneof![
        20 => Just(Input::Nothing),
        2 => request().prop_map(Input::Frame),
        1 => proptest::collection::vec(any::<u8>(), 0..20).prop_map(Input::Garbage),
    ]
}

fn samples() -> impl Strategy<Value = Samples<3>> {
    (
        proptest::array::uniform3((0u16..4096, 0u16..4096)),
        (0u16..4096, 0u16..4096, 0u16..4096),
    )
        .prop_map(|(slots, (filament, tension, cutter))| Samples {
            slots: slots.map(|(motion, filament)| SlotSamples {
                motion,
                filament,
                tension: 2048,
            }),
            hub: HubSamples {
                filament,
                tension,
                cutter,
            },
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// Any bytes and any sensor values: no panic, never two slots fed at once, no phase beyond
    /// its bound, and a `Q0` always gets exactly one well-formed answer.
    #[test]
    fn arbitrary_input_never_panics_or_runs_a_motor_unbounded(
        script in proptest::collection::vec((input(), samples(), 1u64..400), 1..60),
    ) {
        let mut bench = Bench::<3>::default();
        for (input, samples, hold_ms) in script {
            let rx = match &input {
                Input::Nothing => Vec::new(),
                Input::Frame(request) => request.encode().as_bytes().to_vec(),
                Input::Garbage(bytes) => bytes.clone(),
            };
            bench.feed(&rx, &samples, hold_ms).map_err(TestCaseError::fail)?;
        }
    }
}

fn command() -> impl Strategy<Value = Request> {
    prop_oneof![
        (0u8..4).prop_map(|slot| Request::new(RequestCode::Tool, slot)),
        (0u8..3).prop_map(|slot| Request::new(RequestCode::Load, slot)),
        Just(Request::new(RequestCode::Unload, 0)),
        (0u8..3).prop_map(|slot| Request::new(RequestCode::Eject, slot)),
        (0u8..3).prop_map(|slot| Request::new(RequestCode::Cut, slot)),
        Just(Request::new(RequestCode::Home, 0)),
    ]
}

fn fault() -> impl Strategy<Value = Option<Fault>> {
    prop_oneof![
        6 => Just(None),
        1 => (0usize..3).prop_map(|slot| Some(Fault::Jam { slot })),
        1 => Just(Some(Fault::BowdenJam)),
        1 => (0usize..3).prop_map(|slot| Some(Fault::MotorDead { slot })),
        1 => (0usize..3).prop_map(|slot| Some(Fault::SensorDisconnected { sensor: SensorId::MotorHall(slot), rail: Rail::Low })),
        1 => Just(Some(Fault::SensorDisconnected { sensor: SensorId::HubFilament, rail: Rail::High })),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, ..ProptestConfig::default() })]

    /// Random commands and faults against the physical model, recovered as the printer and the
    /// user would: the hub path never holds two slots' filament, and every run ends (finished,
    /// or failed with the motors stopped).
    #[test]
    fn commands_and_faults_never_put_two_slots_past_the_park_position(
        script in proptest::collection::vec((command(), fault()), 1..8),
    ) {
        let mut rig = Rig::<3>::new();
        rig.boot();
        for (request, fault) in script {
            if let Some(fault) = fault {
                rig.inject(fault);
            }
            let answer = rig.send(request).expect("commands are answered");
            if answer.param == mmu_protocol::ParamCode::Accepted {
                let run = rig.follow(request, 120_000);
                if run.last.param == mmu_protocol::ParamCode::Error {
                    rig.idle(300);
                    prop_assert!(rig.motors_stopped(), "motors stop on {:?}", run.last);
                }
            }
            let past_park = (0..3).filter(|&slot| rig.model.tip_mm(slot).is_some_and(|tip| tip > -10.0)).count();
            prop_assert!(past_park <= 1, "{past_park} slots past the park position");
            // The user clears the fault and confirms; the printer's Retry follows.
            rig.model.clear_all();
            if matches!(rig.app.operation().status(), Status::Failed(_)) {
                rig.idle(200);
                rig.send(Request::new(RequestCode::Button, 1));
                rig.follow(rig_request(&rig), 120_000);
            }
        }
    }
}

fn rig_request(rig: &Rig<3>) -> Request {
    let (code, value) = rig.app.operation().request;
    Request::new(code, value)
}
