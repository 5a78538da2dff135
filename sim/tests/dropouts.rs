//! When the simulated printer gives up on a bad line, as Prusa's does: its `DropOutFilter`
//! (`protocol_logic.cpp`, the same in the MK3S's `mmu2_protocol_logic.cpp`) reports
//! MMU_NOT_RESPONDING or PROTOCOL_ERROR after ten link faults in a row, counting both kinds
//! together, and every version answer it accepts (`ProcessVersionResponse` →
//! `ResetCommunicationTimeoutAttempts`) starts the count again. A line that loses a byte now and
//! then costs handshakes, not the session.

use std::io;

use mmu_protocol::{ErrorCode, Request, RequestCode, RequestDecoder, Response, ResultCode};
use mmu_sim::{Decision, Link, Operator, Printer, PrinterError, PrinterOptions};

/// A unit at rest on a line that loses its answer to `S1` the first `lose_s1` times, and to
/// every `S0` when `lose_s0` is set.
struct LossyUnit {
    now: u64,
    decoder: RequestDecoder,
    out: Vec<u8>,
    lose_s1: u32,
    lose_s0: bool,
}

impl LossyUnit {
    fn new(lose_s1: u32, lose_s0: bool) -> Self {
        LossyUnit {
            now: 0,
            decoder: RequestDecoder::new(),
            out: Vec::new(),
            lose_s1,
            lose_s0,
        }
    }

    fn answer(&mut self, request: &Request) -> Option<Response> {
        Some(match request.code {
            RequestCode::Version => {
                let lost = match request.value {
                    0 => self.lose_s0,
                    1 if self.lose_s1 > 0 => {
                        self.lose_s1 -= 1;
                        true
                    }
                    _ => false,
                };
                if lost {
                    return None;
                }
                let version = [3, 0, 3, 896];
                Response::read(request, *version.get(usize::from(request.value))?)
            }
            RequestCode::Query => Response::finished(RequestCode::Reset, 0, ResultCode::OK),
            RequestCode::Read => Response::read(request, 0),
            _ => Response::accepted(request),
        })
    }
}

impl Link for LossyUnit {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        for &byte in bytes {
            if let Some(Ok(request)) = self.decoder.feed(byte)
                && let Some(answer) = self.answer(&request)
            {
                self.out.extend_from_slice(answer.encode().as_bytes());
            }
        }
        Ok(())
    }

    fn receive(&mut self, max_ms: u64, into: &mut Vec<u8>) -> io::Result<()> {
        if self.out.is_empty() {
            self.now += max_ms.max(1);
        } else {
            self.now += 1;
            into.append(&mut self.out);
        }
        Ok(())
    }

    fn now_ms(&self) -> u64 {
        self.now
    }

    fn fsensor(&mut self) -> u8 {
        0
    }
}

struct Nobody;

impl Operator<LossyUnit> for Nobody {
    fn event(&mut self, _link: &mut LossyUnit, _event: &mmu_sim::PrinterEvent) {}

    fn decide(&mut self, _link: &mut LossyUnit, _request: Request, _error: ErrorCode) -> Decision {
        Decision::GiveUp
    }
}

#[test]
fn an_accepted_version_answer_starts_the_drop_out_count_again() {
    // Twelve handshakes in a row fail at `S1`, each after a good `S0`: Prusa's printer never
    // counts more than one drop-out and connects at the thirteenth.
    let mut printer = Printer::new(LossyUnit::new(12, false), PrinterOptions::default());
    let first = printer.connect(&mut Nobody);
    assert!(first.is_ok(), "{first:?}");
}

#[test]
fn ten_drop_outs_without_an_accepted_answer_end_the_session() {
    let mut printer = Printer::new(LossyUnit::new(0, true), PrinterOptions::default());
    let first = printer.connect(&mut Nobody);
    assert!(matches!(first, Err(PrinterError::NotResponding)), "{first:?}");
}
