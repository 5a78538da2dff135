//! Property tests of the codec: every message round-trips byte-exactly, the decoders survive any
//! byte stream, and they always resynchronise after a silence on the line.
//!
//! Case counts are modest so the whole suite runs in a few seconds; the fuzz targets in `fuzz/`
//! are for long runs.

use mmu_protocol::{
    DecodeError, MAX_FRAME_LEN, ParamCode, Request, RequestCode, RequestDecoder, Response, ResponseDecoder,
};
use proptest::prelude::*;

/// An independent, bit-by-bit CRC-8 (poly 0x07, init 0), as in the spec's Python reference.
fn reference_crc(bytes: &[u8]) -> u8 {
    let mut crc = 0u8;
    for &b in bytes {
        crc ^= b;
        for _ in 0..8 {
            crc = if crc & 0x80 != 0 {
                (crc << 1) ^ 0x07
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// The spec's reference formatting of a request (§A), newline included.
fn reference_request_text(request: &Request) -> String {
    let c = request.code.as_char();
    let [lo, hi] = request.value2.to_le_bytes();
    let crc = reference_crc(&[request.code.as_byte(), request.value, lo, hi]);
    if request.code == RequestCode::Write {
        format!("{c}{:x} {:x}*{crc:x}\n", request.value, request.value2)
    } else {
        format!("{c}{:x}*{crc:x}\n", request.value)
    }
}

/// The spec's reference formatting of a response (§A), newline included.
fn reference_response_text(response: &Response) -> String {
    let [lo, hi] = response.param_value.unwrap_or(0).to_le_bytes();
    let crc = reference_crc(&[
        response.code.as_byte(),
        response.value,
        0,
        0,
        response.param.as_byte(),
        lo,
        hi,
    ]);
    let value = response.param_value.map(|v| format!("{v:x}")).unwrap_or_default();
    format!(
        "{}{:x} {}{value}*{crc:x}\n",
        response.code, response.value, response.param
    )
}

fn request_code() -> impl Strategy<Value = RequestCode> {
    prop::sample::select(RequestCode::ALL)
}

fn param_code() -> impl Strategy<Value = ParamCode> {
    prop::sample::select(ParamCode::ALL)
}

/// Any request: any code and value; the written value is any u16 for `W` and 0 otherwise.
fn request() -> impl Strategy<Value = Request> {
    (request_code(), any::<u8>(), any::<u16>()).prop_map(|(code, value, value2)| Request {
        code,
        value,
        value2: if code == RequestCode::Write { value2 } else { 0 },
    })
}

/// Any response: any echoed code and value, any parameter, with or without a printed value.
fn response() -> impl Strategy<Value = Response> {
    (
        request_code(),
        any::<u8>(),
        param_code(),
        proptest::option::of(any::<u16>()),
    )
        .prop_map(|(code, value, param, param_value)| Response {
            code,
            value,
            param,
            param_value,
        })
}

/// Bytes that matter to the decoders (letters, digits, separators, newlines, uppercase hex),
/// mixed with anything at all.
fn noisy_byte() -> impl Strategy<Value = u8> {
    prop_oneof![
        3 => prop::sample::select(b"QTLMUXPSBEWKFfHRAabcdef0123456789ABCDEF *\r\n".to_vec()),
        1 => any::<u8>(),
    ]
}

fn garbage() -> impl Strategy<Value = Vec<u8>> {
    prop_oneof![
        proptest::collection::vec(any::<u8>(), 0..64),
        proptest::collection::vec(noisy_byte(), 0..64),
    ]
}

fn decode_requests(bytes: &[u8]) -> Vec<Result<Request, DecodeError<Request>>> {
    let mut decoder = RequestDecoder::new();
    bytes.iter().filter_map(|&b| decoder.feed(b)).collect()
}

fn decode_responses(bytes: &[u8]) -> Vec<Result<Response, DecodeError<Response>>> {
    let mut decoder = ResponseDecoder::new();
    bytes.iter().filter_map(|&b| decoder.feed(b)).collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1000))]

    #[test]
    fn every_request_round_trips(request in request()) {
        let frame = request.encode();
        let expected = reference_request_text(&request);
        prop_assert_eq!(frame.as_bytes(), expected.as_bytes());
        prop_assert!(frame.as_bytes().len() <= MAX_FRAME_LEN);
        prop_assert_eq!(decode_requests(frame.as_bytes()), vec![Ok(request)]);
    }

    #[test]
    fn every_response_round_trips(response in response()) {
        let frame = response.encode();
        let expected = reference_response_text(&response);
        prop_assert_eq!(frame.as_bytes(), expected.as_bytes());
        prop_assert!(frame.as_bytes().len() <= MAX_FRAME_LEN);
        prop_assert_eq!(decode_responses(frame.as_bytes()), vec![Ok(response)]);
    }

    #[test]
    fn a_stream_of_requests_decodes_in_order(requests in proptest::collection::vec(request(), 0..8)) {
        let bytes: Vec<u8> = requests.iter().flat_map(|r| r.encode().as_bytes().to_vec()).collect();
        let expected: Vec<_> = requests.into_iter().map(Ok).collect();
        prop_assert_eq!(decode_requests(&bytes), expected);
    }

    #[test]
    fn a_stream_of_responses_decodes_in_order(responses in proptest::collection::vec(response(), 0..8)) {
        let bytes: Vec<u8> = responses.iter().flat_map(|r| r.encode().as_bytes().to_vec()).collect();
        let expected: Vec<_> = responses.into_iter().map(Ok).collect();
        prop_assert_eq!(decode_responses(&bytes), expected);
    }

    #[test]
    fn any_bytes_never_panic(bytes in prop_oneof![
        proptest::collection::vec(any::<u8>(), 0..256),
        proptest::collection::vec(noisy_byte(), 0..256),
    ]) {
        // Whatever the decoders accept is a frame whose CRC checks, so it re-encodes to a frame
        // that decodes to itself.
        for request in decode_requests(&bytes).into_iter().flatten() {
            prop_assert_eq!(decode_requests(request.encode().as_bytes()), vec![Ok(request)]);
        }
        for response in decode_responses(&bytes).into_iter().flatten() {
            prop_assert_eq!(decode_responses(response.encode().as_bytes()), vec![Ok(response)]);
        }
    }

    #[test]
    fn a_request_after_garbage_and_a_silence_is_decoded(junk in garbage(), request in request()) {
        let mut decoder = RequestDecoder::new();
        for &b in &junk {
            let _ = decoder.feed(b);
        }
        let _ = decoder.line_silent();
        let bytes = request.encode();
        let (last, body) = bytes.as_bytes().split_last().expect("a frame is never empty");
        for &b in body {
            prop_assert_eq!(decoder.feed(b), None);
        }
        prop_assert_eq!(decoder.feed(*last), Some(Ok(request)));
    }

    #[test]
    fn a_response_after_garbage_and_a_silence_is_decoded(junk in garbage(), response in response()) {
        let mut decoder = ResponseDecoder::new();
        for &b in &junk {
            let _ = decoder.feed(b);
        }
        let _ = decoder.line_silent();
        let bytes = response.encode();
        let (last, body) = bytes.as_bytes().split_last().expect("a frame is never empty");
        for &b in body {
            prop_assert_eq!(decoder.feed(b), None);
        }
        prop_assert_eq!(decoder.feed(*last), Some(Ok(response)));
    }

    #[test]
    fn a_corrupted_crc_is_rejected_and_the_next_frame_survives(
        request in request(),
        flip in 1u8..=255,
    ) {
        let wrong = request.crc() ^ flip;
        let text = reference_request_text(&request);
        let (head, _) = text.rsplit_once('*').expect("a frame has a '*'");
        let corrupted = format!("{head}*{wrong:x}\n");
        let mut bytes = corrupted.into_bytes();
        bytes.extend_from_slice(request.encode().as_bytes());
        let decoded = decode_requests(&bytes);
        prop_assert_eq!(decoded.len(), 2);
        let is_bad_crc = matches!(
            decoded[0],
            Err(DecodeError::BadCrc { frame, computed, received })
                if frame == request && computed == request.crc() && received == wrong
        );
        prop_assert!(is_bad_crc, "{:?}", decoded[0]);
        prop_assert_eq!(decoded[1], Ok(request));
    }
}
