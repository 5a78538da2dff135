//! The body both decoder targets share: feed arbitrary bytes to one decoder and check, besides
//! "never panics":
//! - every accepted frame re-encodes to a frame that decodes to the same frame;
//! - a rejected frame with a bad CRC carries the fields whose CRC it reports;
//! - whatever came before, after a silence on the line a valid frame decodes.

use mmu_protocol::{
    DecodeError, MAX_FRAME_LEN, ParamCode, Request, RequestCode, RequestDecoder, Response, ResponseDecoder,
};

/// What the checks need from a decoder and its frames.
pub trait Decoder {
    type Frame: Copy + PartialEq + core::fmt::Debug;
    fn new() -> Self;
    fn feed(&mut self, byte: u8) -> Option<Result<Self::Frame, DecodeError<Self::Frame>>>;
    fn line_silent(&mut self) -> Option<DecodeError<Self::Frame>>;
    fn encode(frame: &Self::Frame) -> Vec<u8>;
    fn crc(frame: &Self::Frame) -> u8;
    /// A valid frame to send after the noise.
    fn sample() -> Self::Frame;
}

impl Decoder for RequestDecoder {
    type Frame = Request;
    fn new() -> Self {
        RequestDecoder::new()
    }
    fn feed(&mut self, byte: u8) -> Option<Result<Request, DecodeError<Request>>> {
        RequestDecoder::feed(self, byte)
    }
    fn line_silent(&mut self) -> Option<DecodeError<Request>> {
        RequestDecoder::line_silent(self)
    }
    fn encode(frame: &Request) -> Vec<u8> {
        frame.encode().as_bytes().to_vec()
    }
    fn crc(frame: &Request) -> u8 {
        frame.crc()
    }
    fn sample() -> Request {
        Request::new(RequestCode::Query, 0)
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
    fn line_silent(&mut self) -> Option<DecodeError<Response>> {
        ResponseDecoder::line_silent(self)
    }
    fn encode(frame: &Response) -> Vec<u8> {
        frame.encode().as_bytes().to_vec()
    }
    fn crc(frame: &Response) -> u8 {
        frame.crc()
    }
    fn sample() -> Response {
        Response::with_value(RequestCode::Reset, 0, ParamCode::Finished, 0)
    }
}

/// Runs every check on `data`.
pub fn check<D: Decoder>(data: &[u8]) {
    let mut decoder = D::new();
    for &byte in data {
        match decoder.feed(byte) {
            Some(Ok(frame)) => check_round_trip::<D>(frame),
            Some(Err(DecodeError::BadCrc {
                frame,
                computed,
                received,
            })) => {
                assert_ne!(computed, received);
                assert_eq!(D::crc(&frame), computed);
            }
            _ => {}
        }
    }

    // Resynchronisation: after a silence the decoder is ready for a fresh frame.
    let _ = decoder.line_silent();
    let sample = D::sample();
    let results: Vec<_> = D::encode(&sample)
        .iter()
        .filter_map(|&b| decoder.feed(b))
        .collect();
    assert_eq!(results, [Ok(sample)]);
}

fn check_round_trip<D: Decoder>(frame: D::Frame) {
    let bytes = D::encode(&frame);
    assert!(bytes.len() <= MAX_FRAME_LEN);
    let mut fresh = D::new();
    let results: Vec<_> = bytes.iter().filter_map(|&b| fresh.feed(b)).collect();
    assert_eq!(results, [Ok(frame)], "{bytes:?}");
}
