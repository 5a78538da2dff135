//! The simulated unit takes received bytes as the board does: at most
//! `control::MAX_RX_PER_STEP` a step, the rest waiting in the NUCLEO-G071RB's DMA ring of
//! `uart::G071_DMA_RING` bytes, so what the simulator shows of a burst is what the firmware
//! does with it.

use mmu_firmware::control::MAX_RX_PER_STEP;
use mmu_firmware::uart::G071_DMA_RING as RX_RING;
use mmu_protocol::{Request, RequestCode, ResponseDecoder};
use mmu_sim::{Sim, SimOptions};

/// A unit past its start-up check, listening.
fn listening_unit() -> Sim {
    let mut sim = Sim::new(SimOptions::default()).unwrap();
    for _ in 0..5000 {
        sim.step(&[], &mut Vec::new());
    }
    sim
}

/// Sends `requests` in one millisecond, then steps until every answer came (at most 1 s);
/// returns how many answers each step brought, from the burst's step on.
fn answers_per_step(sim: &mut Sim, requests: &[Request]) -> Vec<usize> {
    let burst: Vec<u8> = requests
        .iter()
        .flat_map(|r| r.encode().as_bytes().to_vec())
        .collect();
    let mut decoder = ResponseDecoder::new();
    let mut per_step = Vec::new();
    let mut rx = burst;
    let mut answered = 0;
    while answered < requests.len() && per_step.len() < 1000 {
        let mut tx = Vec::new();
        sim.step(&std::mem::take(&mut rx), &mut tx);
        let answers = tx
            .iter()
            .filter(|&&b| matches!(decoder.feed(b), Some(Ok(_))))
            .count();
        answered += answers;
        per_step.push(answers);
    }
    // Only the steps that answered (the failure messages stay short).
    while per_step.last() == Some(&0) {
        per_step.pop();
    }
    per_step
}

#[test]
fn a_burst_of_requests_is_answered_over_several_steps_as_on_the_board() {
    let mut sim = listening_unit();
    let requests = vec![Request::new(RequestCode::Version, 0); 10];
    let per_step = answers_per_step(&mut sim, &requests);

    assert_eq!(
        per_step.iter().sum::<usize>(),
        10,
        "every request answered: {per_step:?}"
    );
    // Six bytes a request: a step completes at most two.
    let most = MAX_RX_PER_STEP / 6;
    assert!(
        per_step.iter().all(|&n| n <= most),
        "at most {most} answers a step: {per_step:?}"
    );
    assert!(
        per_step.len() >= 10 * 6 / MAX_RX_PER_STEP,
        "spread over steps: {per_step:?}"
    );
}

#[test]
fn bytes_that_lap_the_receive_ring_are_lost_as_on_the_board() {
    let mut sim = listening_unit();
    // Twice what the ring holds, in one millisecond: no printer sends this.
    let count = 2 * RX_RING / 6;
    let requests = vec![Request::new(RequestCode::Version, 0); count];
    let per_step = answers_per_step(&mut sim, &requests);
    let answered: usize = per_step.iter().sum();

    assert!(answered < count, "some lost: {answered} of {count} answered");
    assert!(
        answered >= RX_RING / 6 - 1,
        "what the ring held last is answered: {answered}"
    );
    // The unit still answers afterwards.
    let per_step = answers_per_step(&mut sim, &[Request::new(RequestCode::Query, 0)]);
    assert_eq!(per_step.iter().sum::<usize>(), 1);
}
