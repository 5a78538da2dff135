//! The printer's side of the unit: the link as the printer drives it. Requests are decoded from
//! the line, the revision is negotiated, a button waits for the printer to collect it, and each
//! answer is framed into the step's transmit buffer; what the requests do is [`crate::App`]'s.

use heapless::Vec;
use mmu_protocol::{ButtonCode, MAX_FRAME_LEN, Request, RequestCode, RequestDecoder, Response};

use crate::config::offered_revision;
use crate::phases::PrinterLink;
use crate::time::Instant;

/// The printer link's state across steps.
#[derive(Clone)]
pub struct Session {
    decoder: RequestDecoder,
    negotiation: Negotiation,
    /// A physical button press waiting for the printer to collect it with `Q0` (during `T`, the
    /// printer is in charge of buttons and sends them back).
    pub pending_button: Option<ButtonCode>,
    /// The link as the phases that depend on it see it (`P1c`, `P7` hold their motor while it is
    /// in doubt).
    pub printer: PrinterLink,
    /// Responses that did not fit a step's transmit buffer, or the board's (not persisted).
    pub dropped_responses: u16,
}

impl Session {
    /// A link that has heard nothing. The printer may be mid-frame when the unit starts: only a
    /// newline or a silence starts the first frame.
    pub fn new() -> Self {
        Session {
            decoder: RequestDecoder::new_mid_line(),
            negotiation: Negotiation::default(),
            pending_button: None,
            printer: PrinterLink {
                heard: Instant::ZERO,
                polled: Instant::ZERO,
                in_sync: true,
            },
            dropped_responses: 0,
        }
    }

    /// A step begins at `now` with `rx` received: the last step's answers have gone out, and a
    /// silence on the line ends any frame (what was dropped is not a request).
    pub fn begin_step(&mut self, now: Instant, rx: &[u8]) {
        self.negotiation.answered_this_step = None;
        if !rx.is_empty() {
            self.printer.heard = now;
        } else if now.millis_since(self.printer.heard) >= u64::from(mmu_protocol::SILENCE_MS)
            && self.decoder.line_silent().is_some()
        {
            self.printer.in_sync = false;
        }
    }

    /// The request `byte` completes, if any. A broken frame (perhaps the printer's `f`) puts
    /// the link out of sync.
    pub fn decode(&mut self, byte: u8) -> Option<Request> {
        match self.decoder.feed(byte)? {
            Ok(request) => Some(request),
            Err(_) => {
                self.printer.in_sync = false;
                None
            }
        }
    }

    /// The unit listens to `request`: an `S0` puts the link out of sync, `f` and `Q` back in.
    pub fn listen(&mut self, request: &Request) {
        match (request.code, request.value) {
            (RequestCode::Version, 0) => self.printer.in_sync = false,
            (RequestCode::FilamentSensor | RequestCode::Query, _) => self.printer.in_sync = true,
            _ => {}
        }
    }

    /// The revision to answer an `S2` with, the cycle starting from `accepted`.
    pub fn offer_revision(&mut self, accepted: u8) -> u8 {
        self.negotiation.offer(accepted)
    }

    /// The revision the last `S2` was answered with, while nothing but `S2` and `S3` followed:
    /// an `S3` now means the printer accepted it.
    pub fn offered_revision(&self) -> Option<u8> {
        self.negotiation.offered
    }

    /// A request other than `S2` was handled.
    pub fn other_request(&mut self, request: &Request) {
        self.negotiation.other_request(request);
    }

    /// Whether `tx` has room for one more answer; counts one dropped when it has not.
    pub fn room_for_answer<const C: usize>(&mut self, tx: &Vec<u8, C>) -> bool {
        let room = tx.capacity() - tx.len() >= MAX_FRAME_LEN;
        if !room {
            self.count_dropped();
        }
        room
    }

    /// Frames `response` into `tx`, or counts it dropped.
    pub fn send<const C: usize>(&mut self, response: Response, tx: &mut Vec<u8, C>) {
        if tx.extend_from_slice(response.encode().as_bytes()).is_err() {
            self.count_dropped();
        }
    }

    /// A response that never reached the line.
    pub fn count_dropped(&mut self) {
        self.dropped_responses = self.dropped_responses.saturating_add(1);
    }
}

impl Default for Session {
    fn default() -> Self {
        Self::new()
    }
}

/// The version handshake as the unit sees it. Prusa's printer sends the same `S2` again after a
/// wrong answer, and `S3` only once `S2` matched (`protocol_logic.cpp` `ProcessVersionResponse`):
/// each repeated `S2` gets the next revision of the cycle ([`offered_revision`]), and the one
/// answered last before `S3` is the one the printer accepted. A printer whose answer came late
/// may run two handshakes interleaved (`S1 S1 S2 S2`): each `S1` opens a handshake whose first
/// `S2` is a first ask, answered with the first revision of the cycle, not a refusal.
#[derive(Debug, Clone, Copy, Default)]
struct Negotiation {
    /// `S1` requests since the last `S0` whose handshake has not asked `S2` yet.
    first_asks_due: u8,
    /// `S2` requests answered in a row (in different steps), none other between.
    repeats: u8,
    /// The revision the last `S2` was answered with, while nothing but `S2` and `S3` followed.
    offered: Option<u8>,
    /// The revision an `S2` of this step was answered with: that answer has not gone out yet, so
    /// an `S2` in the same step was queued before the printer heard it, and gets the same answer
    /// (a burst answered 4, 3, 2, 1, 0 could cost a printer its budget).
    answered_this_step: Option<u8>,
}

impl Negotiation {
    /// The answer to an `S2`, the cycle starting from `accepted`.
    fn offer(&mut self, accepted: u8) -> u8 {
        let first_ask = self.first_asks_due > 0;
        self.first_asks_due = self.first_asks_due.saturating_sub(1);
        if first_ask {
            self.repeats = 0;
        }
        let revision = match self.answered_this_step {
            Some(revision) => revision,
            None => {
                let revision = offered_revision(accepted, self.repeats);
                self.repeats = self.repeats.wrapping_add(1);
                revision
            }
        };
        self.offered = Some(revision);
        self.answered_this_step = Some(revision);
        revision
    }

    /// Any request but `S2` ends a run of them; any but `S3` forgets the last offer; `S1`
    /// opens a handshake, `S0` starts them all again.
    fn other_request(&mut self, request: &Request) {
        self.repeats = 0;
        self.answered_this_step = None;
        match (request.code, request.value) {
            (RequestCode::Version, 0) => self.first_asks_due = 0,
            (RequestCode::Version, 1) => self.first_asks_due = self.first_asks_due.saturating_add(1),
            _ => {}
        }
        if !(request.code == RequestCode::Version && request.value == 3) {
            self.offered = None;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    extern crate std;

    fn feed(session: &mut Session, line: &[u8]) -> Option<Request> {
        line.iter()
            .fold(None, |found, &byte| session.decode(byte).or(found))
    }

    #[test]
    fn a_request_counts_only_after_a_silence_and_a_broken_frame_puts_the_link_out_of_sync() {
        let mut session = Session::new();
        let frame = Request::new(RequestCode::Query, 0).encode();
        let line = frame.as_bytes();
        assert_eq!(feed(&mut session, line), None, "mid-line at start: not a request");
        // A silence on the line: the next frame counts.
        session.begin_step(Instant::from_millis(mmu_protocol::SILENCE_MS.into()), &[]);
        let query = feed(&mut session, line);
        assert_eq!(query.map(|r| r.code), Some(RequestCode::Query));
        let mut broken = std::vec::Vec::from(line);
        let crc = line.len() - 2;
        broken[crc] = if broken[crc] == b'0' { b'1' } else { b'0' };
        assert_eq!(feed(&mut session, &broken), None, "a bad CRC");
        assert!(!session.printer.in_sync);
        session.listen(&Request::new(RequestCode::Query, 0));
        assert!(session.printer.in_sync);
    }

    #[test]
    fn repeated_s2_requests_cycle_through_the_revisions_once_a_step() {
        let mut session = Session::new();
        let first = session.offer_revision(4);
        assert_eq!(session.offer_revision(4), first, "the same step: the same answer");
        session.begin_step(Instant::from_millis(1), b"S2");
        let second = session.offer_revision(4);
        assert_ne!(second, first);
        assert_eq!(session.offered_revision(), Some(second));
        session.other_request(&Request::new(RequestCode::Query, 0));
        assert_eq!(session.offered_revision(), None);
    }

    #[test]
    fn an_answer_that_does_not_fit_is_counted_dropped() {
        let mut session = Session::new();
        let mut tx = Vec::<u8, { MAX_FRAME_LEN + 4 }>::new();
        assert!(session.room_for_answer(&tx));
        session.send(Response::accepted(&Request::new(RequestCode::Query, 0)), &mut tx);
        assert!(!tx.is_empty());
        while tx.len() + MAX_FRAME_LEN <= tx.capacity() {
            let _ = tx.push(b' ');
        }
        let _ = tx.push(b' ');
        assert!(!session.room_for_answer(&tx));
        assert_eq!(session.dropped_responses, 1);
    }
}
