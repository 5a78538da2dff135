//! Line noise never forges a frame (design.md §3: "The link cannot forge a command").
//!
//! Every valid frame is corrupted in every way a noisy cable corrupts one byte: each bit flipped,
//! each byte dropped, each of the 256 byte values inserted at each position. A decoder starting at
//! a line boundary may then accept the original frame (a leading zero, a dropped `0`, a newline
//! before the frame change nothing) or nothing at all. Any other frame it accepts is a phantom: a
//! command the printer never sent. After the line falls silent, the original frame sent again
//! must decode: noise costs at most the frame it hit.
//!
//! One kind of phantom no decoder can see: a dropped or inserted digit inside a 16-bit value (a
//! write's value, a response's parameter value) that yields another value with the same CRC-8.
//! The CRC covers the binary fields, so such a frame is byte for byte what the printer would send
//! for the other value. Those are counted apart and must be only that.
//!
//! Requests are covered exhaustively (every code and value). `W` frames (17 M of them) are sampled:
//! every address with two values, and every hex digit in every position of every field length for
//! three addresses. Responses: every code with every third echoed value.

use mmu_protocol::{DecodeError, ParamCode, Request, RequestCode, RequestDecoder, Response, ResponseDecoder};

/// One way to corrupt a frame at a position.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Corruption {
    Flip { bit: u8 },
    Drop,
    Insert { byte: u8 },
}

impl Corruption {
    /// Every corruption at `at` of a frame `len` bytes long (inserts go before byte `at`; at
    /// `len`, after the newline).
    fn every_at(at: usize, len: usize) -> impl Iterator<Item = Corruption> {
        let in_frame = if at < len { 0..8 } else { 0..0 };
        let flips = in_frame.clone().map(|bit| Corruption::Flip { bit });
        let drop = in_frame.take(1).map(|_| Corruption::Drop);
        let inserts = (0..=255u8).map(|byte| Corruption::Insert { byte });
        flips.chain(drop).chain(inserts)
    }

    /// The corrupted byte (if any) in place of `original`, and how many frame bytes it replaces.
    fn bytes(self, original: Option<u8>) -> (Option<u8>, usize) {
        match self {
            Corruption::Flip { bit } => (original.map(|byte| byte ^ (1 << bit)), 1),
            Corruption::Drop => (None, 1),
            Corruption::Insert { byte } => (Some(byte), 0),
        }
    }
}

/// The two decoders, seen alike.
trait Decoder: Clone {
    type Frame: Copy + PartialEq + core::fmt::Debug;
    fn new() -> Self;
    fn feed(&mut self, byte: u8) -> Option<Result<Self::Frame, DecodeError<Self::Frame>>>;
    fn line_silent(&mut self);
    fn encode(frame: &Self::Frame) -> Vec<u8>;
    /// The same frame to its receiver (a response's `F` and `F0` mean the same).
    fn same(a: &Self::Frame, b: &Self::Frame) -> bool;
    /// `b` differs from `a` only in its 16-bit value and carries the same CRC.
    fn crc_blind(a: &Self::Frame, b: &Self::Frame) -> bool;
}

impl Decoder for RequestDecoder {
    type Frame = Request;
    fn new() -> Self {
        RequestDecoder::new()
    }
    fn feed(&mut self, byte: u8) -> Option<Result<Request, DecodeError<Request>>> {
        RequestDecoder::feed(self, byte)
    }
    fn line_silent(&mut self) {
        let _ = RequestDecoder::line_silent(self);
    }
    fn encode(frame: &Request) -> Vec<u8> {
        frame.encode().as_bytes().to_vec()
    }
    fn same(a: &Request, b: &Request) -> bool {
        a == b
    }
    fn crc_blind(a: &Request, b: &Request) -> bool {
        (a.code, a.value) == (b.code, b.value) && a.code == RequestCode::Write && a.crc() == b.crc()
    }
}

impl Decoder for ResponseDecoder {
    type Frame = Response;
    fn new() -> Self {
        ResponseDecoder::new()
    }
    fn feed(&mut self, byte: u8) -> Option<Result<Response, DecodeError<Response>>> {
        ResponseDecoder::feed(self, byte)
    }
    fn line_silent(&mut self) {
        let _ = ResponseDecoder::line_silent(self);
    }
    fn encode(frame: &Response) -> Vec<u8> {
        frame.encode().as_bytes().to_vec()
    }
    fn same(a: &Response, b: &Response) -> bool {
        (a.code, a.value, a.param, a.param_value.unwrap_or(0))
            == (b.code, b.value, b.param, b.param_value.unwrap_or(0))
    }
    fn crc_blind(a: &Response, b: &Response) -> bool {
        (a.code, a.value, a.param) == (b.code, b.value, b.param) && a.crc() == b.crc()
    }
}

/// What a run found.
struct Tally<F> {
    /// Corrupted frames fed.
    cases: usize,
    /// Frames accepted that the printer never sent, with the corruption that gave them.
    phantoms: Vec<(usize, Corruption, F)>,
    /// Phantoms the CRC-8 cannot see (see the module header).
    crc_blind: usize,
}

/// Feeds every corruption of `original` to a decoder starting at a line boundary and records every
/// accepted frame that is not the original. After a flip or a drop (wherever it left the
/// decoder), a silence and the original sent again must decode.
fn corrupt_and_decode<D: Decoder>(original: D::Frame, tally: &mut Tally<D::Frame>) {
    let frame = D::encode(&original);
    let mut prefix = D::new();
    for at in 0..=frame.len() {
        // The bytes before the corruption are the same for every corruption at `at`; only the
        // whole frame (before an insert after its newline) gives a frame.
        let mut before = 0;
        if let Some(&byte) = at.checked_sub(1).and_then(|i| frame.get(i)) {
            let expected = (at == frame.len()).then_some(Ok(original));
            assert_eq!(prefix.feed(byte), expected, "{frame:?} is one frame");
            before = usize::from(expected.is_some());
        }
        for corruption in Corruption::every_at(at, frame.len()) {
            tally.cases += 1;
            let (middle, replaced) = corruption.bytes(frame.get(at).copied());
            let mut decoder = prefix.clone();
            let rest = frame.get(at + replaced..).unwrap_or(&[]);
            let mut originals = before;
            for accepted in middle.iter().chain(rest).filter_map(|&b| decoder.feed(b)?.ok()) {
                if D::same(&accepted, &original) {
                    originals += 1;
                } else if D::crc_blind(&original, &accepted) && !matches!(corruption, Corruption::Flip { .. })
                {
                    tally.crc_blind += 1;
                } else {
                    tally.phantoms.push((at, corruption, accepted));
                }
            }
            assert!(
                originals <= 1,
                "{corruption:?} at {at} of {frame:?} gave the frame twice"
            );

            if !matches!(corruption, Corruption::Insert { .. }) {
                decoder.line_silent();
                let again: Vec<_> = frame.iter().filter_map(|&b| decoder.feed(b)).collect();
                assert_eq!(
                    again,
                    [Ok(original)],
                    "{corruption:?} at {at} of {frame:?}, a silence"
                );
            }
        }
    }
}

fn run<D: Decoder>(frames: impl IntoIterator<Item = D::Frame>) -> Tally<D::Frame> {
    let mut tally = Tally {
        cases: 0,
        phantoms: Vec::new(),
        crc_blind: 0,
    };
    for frame in frames {
        corrupt_and_decode::<D>(frame, &mut tally);
    }
    let shown: Vec<_> = tally.phantoms.iter().take(8).collect();
    println!(
        "{} corrupted frames: {} phantoms, {} CRC-blind value edits",
        tally.cases,
        tally.phantoms.len(),
        tally.crc_blind
    );
    assert!(
        tally.phantoms.is_empty(),
        "{} phantoms in {} corrupted frames, e.g. {shown:?}",
        tally.phantoms.len(),
        tally.cases
    );
    tally
}

/// 16-bit values with every hex digit first, in the middle and last, in every field length
/// (`b`, `e` and `f` are one bit away from the request letters `B`, `E`, `F`).
fn sixteen_bit_values() -> Vec<u16> {
    let mut values: Vec<u16> = (0..16)
        .flat_map(|d| [d, 0x10 | d, 0x101 | d << 4, 0x1021 | d << 8, 0x321 | d << 12])
        .collect();
    values.sort_unstable();
    values.dedup();
    values
}

#[test]
fn no_single_byte_corruption_of_a_request_forges_another() {
    let requests = RequestCode::ALL
        .iter()
        .filter(|&&code| code != RequestCode::Write)
        .flat_map(|&code| (0..=255).map(move |value| Request::new(code, value)));
    let tally = run::<RequestDecoder>(requests);
    assert_eq!(tally.crc_blind, 0);
}

#[test]
fn no_single_byte_corruption_of_a_write_forges_another() {
    let every_address =
        (0..=255).flat_map(|address| [0x97e, 0xbeef].map(|value| Request::write(address, value)));
    let every_digit = [0x00, 0x1b, 0xfe].into_iter().flat_map(|address| {
        sixteen_bit_values()
            .into_iter()
            .map(move |value| Request::write(address, value))
    });
    run::<RequestDecoder>(every_address.chain(every_digit));
}

#[test]
fn no_single_byte_corruption_of_a_response_forges_another() {
    // Every echoed code with every third value; the parameter and its value (every field length,
    // the digits next to letters, a real error code) go round with the value.
    let param_values = [
        None,
        Some(0),
        Some(0xf),
        Some(0xbe),
        Some(0x97e),
        Some(0x8005),
        Some(0xf1ef),
    ];
    let responses = RequestCode::ALL.iter().flat_map(|&code| {
        (0..=255u8).step_by(3).map(move |value| Response {
            code,
            value,
            param: ParamCode::ALL[usize::from(value) % ParamCode::ALL.len()],
            param_value: param_values[usize::from(value) % param_values.len()],
        })
    });
    run::<ResponseDecoder>(responses);
}
