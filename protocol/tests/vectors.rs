//! Every test vector of the wire specification (`prusa-mmu-protocol.md` §2.5, §3.4 and §8.3),
//! in both directions: the encoder must produce the bytes exactly (trailing `\n` included) and
//! the decoder must give the same struct back.
//!
//! §8.3 #21-#25 describe Prusa's stricter decoder (a CRC error or a CRLF costs the next line).
//! Ours resynchronises at once; those rows assert our documented behaviour instead.

use mmu_protocol::{
    ButtonCode, DecodeError, ErrorCode, ParamCode, ProgressCode, Request, RequestCode, RequestDecoder,
    Response, ResponseDecoder, ResultCode,
};

type RequestResult = Result<Request, DecodeError<Request>>;
type ResponseResult = Result<Response, DecodeError<Response>>;

/// The request code for a letter of the spec's tables.
fn code(letter: char) -> RequestCode {
    RequestCode::from_byte(letter as u8).unwrap_or_else(|| panic!("{letter:?} is no request code"))
}

/// The parameter code for a letter of the spec's tables.
fn param(letter: char) -> ParamCode {
    ParamCode::from_byte(letter as u8).unwrap_or_else(|| panic!("{letter:?} is no param code"))
}

fn req(letter: char, value: u8) -> Request {
    Request::new(code(letter), value)
}

fn rsp(letter: char, value: u8, param_letter: char, param_value: Option<u16>) -> Response {
    Response {
        code: code(letter),
        value,
        param: param(param_letter),
        param_value,
    }
}

/// Everything the request decoder reports for `bytes`, in order.
fn decode_requests(bytes: &[u8]) -> Vec<RequestResult> {
    let mut decoder = RequestDecoder::new();
    bytes.iter().filter_map(|&b| decoder.feed(b)).collect()
}

/// Everything the response decoder reports for `bytes`, in order.
fn decode_responses(bytes: &[u8]) -> Vec<ResponseResult> {
    let mut decoder = ResponseDecoder::new();
    bytes.iter().filter_map(|&b| decoder.feed(b)).collect()
}

fn ok_requests(bytes: &[u8]) -> Vec<Request> {
    decode_requests(bytes)
        .into_iter()
        .filter_map(Result::ok)
        .collect()
}

fn ok_responses(bytes: &[u8]) -> Vec<Response> {
    decode_responses(bytes)
        .into_iter()
        .filter_map(Result::ok)
        .collect()
}

/// `request` encodes to `wire` + `\n` byte for byte, and those bytes decode to `request` alone.
fn check_request(request: Request, wire: &str) {
    let expected = format!("{wire}\n");
    let frame = request.encode();
    assert_eq!(
        frame.as_bytes(),
        expected.as_bytes(),
        "encoding {request:?}: got {frame:?}, want {wire:?}"
    );
    assert_eq!(frame.as_str(), wire);
    assert_eq!(frame.to_string(), wire);
    assert_eq!(request.crc(), crc_of(wire), "crc of {wire:?}");
    assert_eq!(
        decode_requests(expected.as_bytes()),
        vec![Ok(request)],
        "decoding {wire:?}"
    );
}

/// `response` encodes to `wire` + `\n` byte for byte, and those bytes decode to `response` alone.
fn check_response(response: Response, wire: &str) {
    let expected = format!("{wire}\n");
    let frame = response.encode();
    assert_eq!(
        frame.as_bytes(),
        expected.as_bytes(),
        "encoding {response:?}: got {frame:?}, want {wire:?}"
    );
    assert_eq!(frame.as_str(), wire);
    assert_eq!(response.crc(), crc_of(wire), "crc of {wire:?}");
    assert_eq!(
        decode_responses(expected.as_bytes()),
        vec![Ok(response)],
        "decoding {wire:?}"
    );
}

/// The CRC printed after the `*` of a frame's text.
fn crc_of(wire: &str) -> u8 {
    let (_, crc) = wire.rsplit_once('*').expect("a frame has a '*'");
    u8::from_str_radix(crc, 16).expect("the CRC is hex")
}

// ---------------------------------------------------------------------------------------------
// §2.5 Example requests
// ---------------------------------------------------------------------------------------------

#[test]
fn spec_2_5_example_requests() {
    let vectors: &[(Request, &str)] = &[
        (req('Q', 0), "Q0*ea"),
        (req('S', 0), "S0*c6"),
        (req('S', 1), "S1*ad"),
        (req('S', 2), "S2*10"),
        (req('S', 3), "S3*7b"),
        (req('T', 0), "T0*a4"),
        (req('T', 1), "T1*cf"),
        (req('T', 2), "T2*72"),
        (req('T', 3), "T3*19"),
        (req('T', 4), "T4*f"),
        (req('L', 0), "L0*73"),
        (req('L', 1), "L1*18"),
        (req('L', 2), "L2*a5"),
        (req('L', 3), "L3*ce"),
        (req('L', 4), "L4*d8"),
        (req('U', 0), "U0*b2"),
        (req('E', 0), "E0*d5"),
        (req('E', 1), "E1*be"),
        (req('E', 2), "E2*3"),
        (req('E', 3), "E3*68"),
        (req('E', 4), "E4*7e"),
        (req('K', 0), "K0*11"),
        (req('K', 1), "K1*7a"),
        (req('K', 2), "K2*c7"),
        (req('K', 3), "K3*ac"),
        (req('K', 4), "K4*ba"),
        (req('H', 0), "H0*2b"),
        (req('X', 0), "X0*4c"),
        (req('X', 42), "X2a*88"),
        (req('B', 0), "B0*b7"),
        (req('B', 1), "B1*dc"),
        (req('B', 2), "B2*61"),
        (req('f', 0), "f0*21"),
        (req('f', 1), "f1*4a"),
        (req('f', 2), "f2*f7"),
        (req('f', 3), "f3*9c"),
        (req('P', 0), "P0*fc"),
        (req('R', 0x08), "R8*81"),
        (req('R', 0x1b), "R1b*9e"),
        (req('R', 0x1c), "R1c*88"),
        (req('R', 0x04), "R4*7b"),
        (req('R', 0x1a), "R1a*f5"),
        (req('F', 0), "F0*ef"),
        (req('M', 0), "M0*65"),
        (req('M', 1), "M1*e"),
    ];
    for &(request, wire) in vectors {
        check_request(request, wire);
    }
}

#[test]
fn spec_2_5_full_table_of_main_codes() {
    // Row: code, then the CRC for values 0..=4.
    let table: [(char, [&str; 5]); 15] = [
        ('Q', ["ea", "81", "3c", "57", "41"]),
        ('P', ["fc", "97", "2a", "41", "57"]),
        ('S', ["c6", "ad", "10", "7b", "6d"]),
        ('T', ["a4", "cf", "72", "19", "f"]),
        ('L', ["73", "18", "a5", "ce", "d8"]),
        ('U', ["b2", "d9", "64", "f", "19"]),
        ('E', ["d5", "be", "3", "68", "7e"]),
        ('K', ["11", "7a", "c7", "ac", "ba"]),
        ('H', ["2b", "40", "fd", "96", "80"]),
        ('X', ["4c", "27", "9a", "f1", "e7"]),
        ('B', ["b7", "dc", "61", "a", "1c"]),
        ('f', ["21", "4a", "f7", "9c", "8a"]),
        ('F', ["ef", "84", "39", "52", "44"]),
        ('M', ["65", "e", "b3", "d8", "ce"]),
        ('R', ["d0", "bb", "6", "6d", "7b"]),
    ];
    let mut checked = 0;
    for (letter, crcs) in table {
        for (value, crc) in (0u8..).zip(crcs) {
            check_request(req(letter, value), &format!("{letter}{value}*{crc}"));
            checked += 1;
        }
    }
    assert_eq!(checked, 75);
}

#[test]
fn spec_2_4_write_examples() {
    check_request(Request::write(0x0b, 5), "Wb 5*33");
    check_request(Request::write(0x14, 20), "W14 14*94");
    check_request(Request::write(0x0b, 30), "Wb 1e*f3");
    check_request(Request::write(0x22, 360), "W22 168*51");
    check_request(Request::write(0xfd, 0x4c00), "Wfd 4c00*80");
}

// ---------------------------------------------------------------------------------------------
// §3.4 Example responses
// ---------------------------------------------------------------------------------------------

#[test]
fn spec_3_4_example_responses() {
    let a = |letter, value, pv| rsp(letter, value, 'A', pv);
    let vectors: &[(Response, &str)] = &[
        // Versions S0..S3 for 3.0.3 build 896, and BFW's unit-test build 895.
        (a('S', 0, Some(3)), "S0 A3*22"),
        (a('S', 1, Some(0)), "S1 A0*34"),
        (a('S', 2, Some(3)), "S2 A3*70"),
        (a('S', 3, Some(896)), "S3 A380*d9"),
        (a('S', 3, Some(895)), "S3 A37f*e"),
        // 3.0.2.
        (a('S', 2, Some(2)), "S2 A2*65"),
        // Init writes acked, writes rejected, the MMU unit test's write ack.
        (a('W', 0x0b, None), "Wb A*5c"),
        (a('W', 0x14, None), "W14 A*52"),
        (rsp('W', 0x08, 'R', None), "W8 R*38"),
        (rsp('W', 0x99, 'R', None), "W99 R*63"),
        (a('W', 0x1b, None), "W1b A*c2"),
        // fsensor acks.
        (a('f', 0, None), "f0 A*c5"),
        (a('f', 1, None), "f1 A*ec"),
        (a('f', 2, None), "f2 A*97"),
        (a('f', 3, None), "f3 A*be"),
        // Register reads.
        (a('R', 0x08, Some(0)), "R8 A0*8d"),
        (a('R', 0x08, Some(1)), "R8 A1*98"),
        (a('R', 0x1b, Some(5)), "R1b A5*29"),
        (a('R', 0x1c, Some(5)), "R1c A5*f6"),
        (a('R', 0x04, Some(0)), "R4 A0*66"),
        (a('R', 0x1a, Some(0)), "R1a A0*41"),
        (rsp('R', 0x99, 'R', None), "R99 R*c9"),
        // FINDA query.
        (a('P', 0, Some(0)), "P0 A0*7b"),
        (a('P', 0, Some(1)), "P0 A1*6e"),
        // Idle after boot, start-up error.
        (rsp('X', 0, 'F', Some(0)), "X0 F0*87"),
        (rsp('X', 0, 'E', Some(0x8008)), "X0 E8008*1b"),
        // Commands accepted / rejected.
        (a('T', 0, None), "T0 A*e"),
        (a('T', 1, None), "T1 A*27"),
        (rsp('T', 1, 'R', None), "T1 R*38"),
        (a('L', 0, None), "L0 A*37"),
        (rsp('L', 0, 'R', None), "L0 R*28"),
        (a('U', 0, None), "U0 A*d1"),
        (a('E', 0, None), "E0 A*2"),
        (a('K', 0, None), "K0 A*24"),
        (a('H', 0, None), "H0 A*42"),
        // Progress.
        (rsp('T', 0, 'P', Some(0x03)), "T0 P3*f8"),
        (rsp('T', 0, 'P', Some(0x05)), "T0 P5*86"),
        (rsp('T', 0, 'P', Some(0x06)), "T0 P6*b9"),
        (rsp('T', 0, 'P', Some(0x1c)), "T0 P1c*6c"),
        (rsp('T', 0, 'P', Some(0x07)), "T0 P7*ac"),
        (rsp('T', 0, 'P', Some(0x02)), "T0 P2*ed"),
        (rsp('T', 0, 'P', Some(0x0a)), "T0 Pa*45"),
        (rsp('U', 0, 'P', Some(0x03)), "U0 P3*27"),
        (rsp('K', 0, 'P', Some(0x15)), "K0 P15*fb"),
        (rsp('H', 0, 'P', Some(0x1a)), "H0 P1a*5e"),
        // Errors.
        (rsp('T', 0, 'E', Some(0x8001)), "T0 E8001*39"),
        (rsp('T', 0, 'E', Some(0x8003)), "T0 E8003*13"),
        (rsp('T', 0, 'E', Some(0x8087)), "T0 E8087*f1"),
        (rsp('E', 0, 'E', Some(0x800c)), "E0 E800c*dc"),
        // Buttons from the MMU.
        (rsp('T', 0, 'B', Some(1)), "T0 B1*a6"),
        (rsp('T', 1, 'B', Some(1)), "T1 B1*8f"),
        (rsp('X', 0, 'B', Some(1)), "X0 B1*39"),
        // Finished.
        (rsp('T', 0, 'F', Some(0)), "T0 F0*18"),
        (rsp('T', 1, 'F', Some(0)), "T1 F0*31"),
        (rsp('L', 0, 'F', Some(1)), "L0 F1*34"),
        (rsp('U', 0, 'F', Some(0)), "U0 F0*c7"),
        (rsp('E', 0, 'F', Some(0)), "E0 F0*14"),
        (rsp('K', 0, 'F', Some(0)), "K0 F0*32"),
        (rsp('H', 0, 'F', Some(0)), "H0 F0*54"),
        // Button acks.
        (a('B', 0, None), "B0 A*11"),
        (a('B', 1, None), "B1 A*38"),
        (a('B', 2, None), "B2 A*43"),
        // The BFW MODBUS-bridge log example.
        (a('W', 0xfd, None), "Wfd A*95"),
    ];
    for &(response, wire) in vectors {
        check_response(response, wire);
    }
}

#[test]
fn spec_3_4_accept_reject_table() {
    // Row: echoed code, slots, then the CRCs of `A` and of `R` for each slot.
    type Row = (
        char,
        &'static [u8],
        &'static [&'static str],
        &'static [&'static str],
    );
    let table: &[Row] = &[
        (
            'T',
            &[0, 1, 2, 3, 4],
            &["e", "27", "5c", "75", "aa"],
            &["11", "38", "43", "6a", "b5"],
        ),
        (
            'L',
            &[0, 1, 2, 3, 4],
            &["37", "1e", "65", "4c", "93"],
            &["28", "1", "7a", "53", "8c"],
        ),
        (
            'E',
            &[0, 1, 2, 3, 4],
            &["2", "2b", "50", "79", "a6"],
            &["1d", "34", "4f", "66", "b9"],
        ),
        (
            'K',
            &[0, 1, 2, 3, 4],
            &["24", "d", "76", "5f", "80"],
            &["3b", "12", "69", "40", "9f"],
        ),
        ('U', &[0], &["d1"], &["ce"]),
        ('H', &[0], &["42"], &["5d"]),
    ];
    let mut checked = 0;
    for &(letter, slots, accepted, rejected) in table {
        for ((&slot, a_crc), r_crc) in slots.iter().zip(accepted).zip(rejected) {
            let request = req(letter, slot);
            check_response(Response::accepted(&request), &format!("{letter}{slot} A*{a_crc}"));
            check_response(Response::rejected(&request), &format!("{letter}{slot} R*{r_crc}"));
            checked += 2;
        }
    }
    assert_eq!(checked, 44);
}

#[test]
fn response_constructors_match_the_examples() {
    let s0 = req('S', 0);
    assert_eq!(Response::read(&s0, 3).encode().as_str(), "S0 A3*22");
    assert_eq!(
        Response::progress(RequestCode::Tool, 0, ProgressCode::FEEDING_TO_FSENSOR)
            .encode()
            .as_str(),
        "T0 P1c*6c"
    );
    assert_eq!(
        Response::error(RequestCode::Eject, 0, ErrorCode::FILAMENT_EJECTED)
            .encode()
            .as_str(),
        "E0 E800c*dc"
    );
    assert_eq!(
        Response::finished(RequestCode::Load, 0, ResultCode::CANCELLED)
            .encode()
            .as_str(),
        "L0 F1*34"
    );
    assert_eq!(
        Response::button(RequestCode::Reset, 0, ButtonCode::MIDDLE)
            .encode()
            .as_str(),
        "X0 B1*39"
    );
    assert_eq!(
        Response::bare(RequestCode::Write, 0x1b, ParamCode::Accepted)
            .encode()
            .as_str(),
        "W1b A*c2"
    );
}

// ---------------------------------------------------------------------------------------------
// §8.3 Vectors #1-#30
// ---------------------------------------------------------------------------------------------

#[test]
fn spec_8_3_encode_requests_1_to_10() {
    let vectors: &[(Request, &[u8])] = &[
        (Request::new(RequestCode::Query, 0), b"Q0*ea\n"),   // #1
        (Request::new(RequestCode::Version, 0), b"S0*c6\n"), // #2
        (Request::new(RequestCode::Load, 0), b"L0*73\n"),    // #3
        (Request::new(RequestCode::Tool, 4), b"T4*f\n"),     // #4
        (Request::new(RequestCode::Reset, 42), b"X2a*88\n"), // #5
        (Request::new(RequestCode::Reset, 0), b"X0*4c\n"),   // #6
        (Request::new(RequestCode::FilamentSensor, 2), b"f2*f7\n"), // #7
        (Request::write(0x0b, 5), b"Wb 5*33\n"),             // #8
        (Request::write(0x14, 20), b"W14 14*94\n"),          // #9
        (Request::write(0x22, 360), b"W22 168*51\n"),        // #10
    ];
    for &(request, bytes) in vectors {
        assert_eq!(request.encode().as_bytes(), bytes, "{request:?}");
        assert_eq!(decode_requests(bytes), vec![Ok(request)]);
    }
}

#[test]
fn spec_8_3_encode_responses_11_to_18() {
    let s0 = Request::new(RequestCode::Version, 0);
    let vectors: &[(Response, &[u8])] = &[
        (Response::read(&s0, 3), b"S0 A3*22\n"), // #11
        // #12: the write's value2 (2) must not enter the CRC (it would give 0x06).
        (Response::accepted(&Request::write(0x1b, 2)), b"W1b A*c2\n"),
        (Response::accepted(&Request::write(0xfd, 7)), b"Wfd A*95\n"), // #13
        (
            Response::finished(RequestCode::Reset, 0, ResultCode::OK), // #14
            b"X0 F0*87\n",
        ),
        (
            Response::progress(RequestCode::Tool, 0, ProgressCode(0x1c)), // #15
            b"T0 P1c*6c\n",
        ),
        (
            Response::error(RequestCode::Tool, 0, ErrorCode(0x8003)), // #16
            b"T0 E8003*13\n",
        ),
        (
            Response::button(RequestCode::Tool, 1, ButtonCode::MIDDLE), // #17
            b"T1 B1*8f\n",
        ),
        (
            Response::rejected(&Request::new(RequestCode::Read, 0x99)), // #18
            b"R99 R*c9\n",
        ),
    ];
    for &(response, bytes) in vectors {
        assert_eq!(response.encode().as_bytes(), bytes, "{response:?}");
        assert_eq!(decode_responses(bytes), vec![Ok(response)]);
    }
}

#[test]
fn spec_8_3_19_decode_load() {
    let mut decoder = RequestDecoder::new();
    let steps: Vec<_> = b"L0*73\n".iter().map(|&b| decoder.feed(b)).collect();
    // `.....C`: nothing until the newline completes the frame.
    assert!(steps[..5].iter().all(Option::is_none), "{steps:?}");
    assert_eq!(steps[5], Some(Ok(Request::new(RequestCode::Load, 0))));
}

#[test]
fn spec_8_3_20_decode_write() {
    let decoded = decode_requests(b"Wb 5*33\n");
    assert_eq!(decoded, vec![Ok(Request::write(0x0b, 5))]);
    let Ok(request) = decoded[0] else { unreachable!() };
    assert_eq!(request.code, RequestCode::Write);
    assert_eq!(request.value, 0x0b);
    assert_eq!(request.value2, 5);
}

#[test]
fn spec_8_3_21_bad_crc_is_rejected_with_its_fields() {
    // Prusa: Error, code unknown, decoder stuck in Error. Ours: BadCrc with the fields kept.
    assert_eq!(
        decode_requests(b"B0*aa\n"),
        vec![Err(DecodeError::BadCrc {
            frame: Request::new(RequestCode::Button, 0),
            computed: 0xb7,
            received: 0xaa,
        })]
    );
}

#[test]
fn spec_8_3_22_the_line_after_a_crc_error_is_not_lost() {
    // Prusa loses the first Q0 after the CRC error; ours decodes the very next one.
    let q0 = Request::new(RequestCode::Query, 0);
    let decoded = decode_requests(b"B0*aa\nQ0*ea\nQ0*ea\n");
    assert_eq!(decoded.len(), 3, "{decoded:?}");
    assert!(matches!(decoded[0], Err(DecodeError::BadCrc { .. })));
    assert_eq!(decoded[1], Ok(q0));
    assert_eq!(decoded[2], Ok(q0));

    let mut decoder = RequestDecoder::new();
    let mut results = b"B0*aa\nQ0*ea\n".iter().filter_map(|&b| decoder.feed(b));
    assert!(matches!(results.next(), Some(Err(DecodeError::BadCrc { .. }))));
    assert_eq!(results.next(), Some(Ok(q0)));
    assert_eq!(results.next(), None);
}

#[test]
fn spec_8_3_23_crlf_costs_nothing() {
    // Prusa: the `\n` after the `\r` errors and eats the next line. Ours: two Q0, nothing else.
    let q0 = Request::new(RequestCode::Query, 0);
    assert_eq!(decode_requests(b"Q0*ea\r\nQ0*ea\n"), vec![Ok(q0), Ok(q0)]);
    // Blank lines and a leading newline are ignored too.
    assert_eq!(
        decode_requests(b"\n\r\n\rQ0*ea\n\n\nQ0*ea\r"),
        vec![Ok(q0), Ok(q0)]
    );
}

#[test]
fn spec_8_3_24_uppercase_hex_is_rejected() {
    let decoded = decode_requests(b"Q0*EA\n");
    assert!(!decoded.is_empty());
    assert!(decoded.iter().all(Result::is_err), "{decoded:?}");
    // ... and the next frame decodes once the line has been silent (a frame broken by a wrong
    // byte may go on after its newline, so nothing right after it is believed).
    let mut decoder = RequestDecoder::new();
    assert!(accepted(&mut decoder, b"Q0*EA\nQ0*ea\n").is_empty());
    assert_eq!(decoder.line_silent(), None);
    assert_eq!(accepted(&mut decoder, b"Q0*ea\n"), [req('Q', 0)]);
    // Uppercase in a value or a response is no better.
    assert!(ok_requests(b"R1B*9e\n").is_empty());
    assert!(ok_responses(b"T0 PA*45\n").is_empty());
    assert!(ok_responses(b"T0 P1C*6c\n").is_empty());
    assert!(ok_responses(b"T0 E800C*dc\n").is_empty());
    assert!(ok_responses(b"T0 Pa*45\n".to_ascii_uppercase().as_slice()).is_empty());
}

#[test]
fn spec_8_3_25_lowercase_b_is_no_request() {
    assert_eq!(
        decode_requests(b"b0\n"),
        vec![Err(DecodeError::UnknownCode(b'b'))]
    );
    // Other cases from Prusa's unit test: a space instead of the CRC, a leading space.
    assert!(ok_requests(b"B1 \n").is_empty());
    assert!(ok_requests(b" B2\n").is_empty());
    assert!(decode_requests(b"B1 \n ").iter().all(Result::is_err));
}

#[test]
fn spec_8_3_26_lenient_values() {
    assert_eq!(
        decode_requests(b"L00*73\n"),
        vec![Ok(Request::new(RequestCode::Load, 0))]
    );
    assert_eq!(
        decode_requests(b"Q*ea\n"),
        vec![Ok(Request::new(RequestCode::Query, 0))]
    );
    // §2.1: a zero-padded CRC, and an 8-bit value keeps its last two digits.
    assert_eq!(
        decode_requests(b"L0*073\n"),
        vec![Ok(Request::new(RequestCode::Load, 0))]
    );
    assert_eq!(
        decode_requests(b"T100*a4\n"),
        vec![Ok(Request::new(RequestCode::Tool, 0))]
    );
}

#[test]
fn spec_8_3_27_response_decoder_skips_leading_crlf() {
    let s0 = Request::new(RequestCode::Version, 0);
    assert_eq!(
        decode_responses(b"\r\nS0 A3*22\n"),
        vec![Ok(Response::read(&s0, 3))]
    );
}

#[test]
fn spec_8_3_28_f_with_and_without_a_value() {
    // The digits never enter the CRC, so both carry the same CRC. Ours keeps what was printed.
    assert_eq!(decode_responses(b"X0 F*87\n"), vec![Ok(rsp('X', 0, 'F', None))]);
    assert_eq!(
        decode_responses(b"X0 F0*87\n"),
        vec![Ok(rsp('X', 0, 'F', Some(0)))]
    );
}

#[test]
fn spec_8_3_29_response_bad_crc_keeps_fields() {
    assert_eq!(
        decode_responses(b"X0 F0*86\n"),
        vec![Err(DecodeError::BadCrc {
            frame: rsp('X', 0, 'F', Some(0)),
            computed: 0x87,
            received: 0x86,
        })]
    );
    // The next line is not lost.
    assert_eq!(
        ok_responses(b"X0 F0*86\nX0 F0*87\n"),
        vec![rsp('X', 0, 'F', Some(0))]
    );
}

#[test]
fn spec_8_3_30_old_firmware_greetings_are_rejected() {
    assert_eq!(
        decode_responses(b"ok\n"),
        vec![Err(DecodeError::UnknownCode(b'o'))]
    );
    assert_eq!(
        decode_responses(b"start\n"),
        vec![Err(DecodeError::UnknownCode(b's'))]
    );
}

// ---------------------------------------------------------------------------------------------
// Our own recovery rules
// ---------------------------------------------------------------------------------------------

/// Feeds `bytes` to `decoder` and keeps what it accepted.
fn accepted(decoder: &mut RequestDecoder, bytes: &[u8]) -> Vec<Request> {
    bytes.iter().filter_map(|&b| decoder.feed(b)?.ok()).collect()
}

#[test]
fn bootloader_probe_then_a_silence_does_not_cost_the_first_frame() {
    // §5.1: the MK4 probes for a bootloader with bare `S` (20 times) and `E` (4 times), 500 ms
    // apart and without a newline, then waits 1 s and sends `S0` (Buddy's
    // `src/mmu2/mmu2_bootloader.cpp`). Each pause is a silence on the line.
    let mut decoder = RequestDecoder::new();
    for &probe in [b'S'; 20].iter().chain(&[b'E'; 4]) {
        assert_eq!(decoder.feed(probe), None);
        assert_eq!(decoder.line_silent(), Some(DecodeError::Interrupted));
    }
    assert_eq!(
        decoder.line_silent(),
        None,
        "a longer silence reports nothing more"
    );
    assert_eq!(accepted(&mut decoder, b"S0*c6\n"), [req('S', 0)]);

    // The same bytes back to back and a single silence before `S0` cost nothing either.
    let mut decoder = RequestDecoder::new();
    let probe = [[b'S'; 20].as_slice(), &[b'E'; 4]].concat();
    assert!(accepted(&mut decoder, &probe).is_empty());
    assert_eq!(decoder.line_silent(), Some(DecodeError::UnexpectedByte(b'S')));
    assert_eq!(accepted(&mut decoder, b"S0*c6\n"), [req('S', 0)]);
}

#[test]
fn a_frame_letter_inside_a_broken_frame_starts_nothing() {
    // The phantoms of issue 12: one flipped bit (`e`, `f`, `b` to `E`, `F`, `B`) or one inserted
    // letter, and the old decoder read the tail as a command the printer never sent.
    for phantom in [
        &b"W0 97E*d5\n"[..],
        b"Q3fX*4c\n",
        b"Q1bT*a4\n",
        b"W0 42F*ef\n",
        b"T0*Q0*ea\n",
        b"SSSES0*c6\n",
    ] {
        assert_eq!(ok_requests(phantom), [], "{:?}", String::from_utf8_lossy(phantom));
    }
    assert_eq!(
        decode_requests(b"W0 97E*d5\n"),
        [Err(DecodeError::UnexpectedByte(b'E'))]
    );
    // Responses alike: `Q6ce P*cb` with `e` flipped to `E` is not `E0 P`.
    assert_eq!(ok_responses(b"Q6cE P*cb\n"), []);
}

#[test]
fn after_a_broken_frame_nothing_decodes_until_the_line_falls_silent() {
    // A newline inserted before a write's `f` digit: the tail `f*21` is a valid `f0` frame, but it
    // is the broken frame's own tail. The printer sends nothing more before its 2 s timeout.
    let mut decoder = RequestDecoder::new();
    let results: Vec<_> = b"W71 bee\nf*21\nQ0*ea\n"
        .iter()
        .filter_map(|&b| decoder.feed(b))
        .collect();
    assert_eq!(
        results,
        [
            Err(DecodeError::Incomplete),
            Err(DecodeError::AfterBrokenFrame),
            Err(DecodeError::AfterBrokenFrame),
        ]
    );
    assert_eq!(decoder.line_silent(), None);
    assert_eq!(
        accepted(&mut decoder, b"W71 beef*21\n"),
        [Request::write(0x71, 0xbeef)]
    );

    // A broken line without its newline ends at the silence as well.
    let mut decoder = RequestDecoder::new();
    assert!(accepted(&mut decoder, b"T1*cZ").is_empty());
    assert_eq!(decoder.line_silent(), Some(DecodeError::UnexpectedByte(b'Z')));
    assert_eq!(accepted(&mut decoder, b"T1*cf\n"), [req('T', 1)]);

    let mut decoder = ResponseDecoder::new();
    let got: Vec<_> = b"T\nf A*xx\n".iter().filter_map(|&b| decoder.feed(b)).collect();
    assert!(got.iter().all(Result::is_err), "{got:?}");
    assert_eq!(decoder.line_silent(), None);
    let s0 = Request::new(RequestCode::Version, 0);
    let got: Vec<_> = b"S0 A3*22\n".iter().filter_map(|&b| decoder.feed(b)).collect();
    assert_eq!(got, [Ok(Response::read(&s0, 3))]);
}

#[test]
fn a_decoder_joining_mid_line_waits_for_a_silence() {
    // The unit booted while the printer was sending `W71 beef*21`: its tail `f*21` is a valid `f0`.
    let mut decoder = RequestDecoder::new_mid_line();
    assert!(accepted(&mut decoder, b"f*21\nQ0*ea\n").is_empty());
    assert_eq!(decoder.line_silent(), None);
    assert_eq!(accepted(&mut decoder, b"Q0*ea\n"), [req('Q', 0)]);

    let mut decoder = ResponseDecoder::new_mid_line();
    assert!(
        b"X0 F0*87\n"
            .iter()
            .all(|&b| decoder.feed(b).is_none_or(|r| r.is_err()))
    );
    assert_eq!(decoder.line_silent(), None);
    let got: Vec<_> = b"X0 F0*87\n".iter().filter_map(|&b| decoder.feed(b)).collect();
    assert_eq!(got, [Ok(rsp('X', 0, 'F', Some(0)))]);
}

#[test]
fn a_line_that_never_began_a_frame_costs_nothing() {
    // Garbage that never began a frame, then a newline: the next frame decodes at once.
    for garbage in [&b"zzzz\n"[..], b"ok\r\n", b"start\n", b"\x00\xff 12*\n", b"*\n"] {
        let mut bytes = garbage.to_vec();
        bytes.extend_from_slice(b"Q0*ea\n");
        assert_eq!(
            ok_requests(&bytes),
            [req('Q', 0)],
            "{:?}",
            String::from_utf8_lossy(garbage)
        );
    }
    // So does a frame with a bad CRC (its newline ends it: §8.3.29 for responses).
    assert_eq!(ok_requests(b"T1*ce\nT1*cf\n"), [req('T', 1)]);
}

#[test]
fn crlf_and_blank_lines_are_skipped() {
    assert_eq!(
        decode_requests(b"\r\n\r\nQ0*ea\r\n\n\nT1*cf\r\n"),
        [Ok(req('Q', 0)), Ok(req('T', 1))]
    );
    let s0 = Request::new(RequestCode::Version, 0);
    assert_eq!(
        decode_responses(b"\r\nS0 A3*22\r\n\r\nS0 A3*22\n"),
        [Ok(Response::read(&s0, 3)), Ok(Response::read(&s0, 3))]
    );
}

#[test]
fn leading_zeros_and_an_empty_value_are_accepted_as_by_prusa() {
    assert_eq!(
        ok_requests(b"L00*73\nQ*ea\nW00 00ff*49\n"),
        [req('L', 0), req('Q', 0), Request::write(0, 0xff)]
    );
}

#[test]
fn truncated_lines_are_incomplete() {
    assert_eq!(decode_requests(b"T0\n"), vec![Err(DecodeError::Incomplete)]);
    assert_eq!(decode_responses(b"T0 A\n"), vec![Err(DecodeError::Incomplete)]);
}

#[test]
fn the_two_decoders_do_not_take_each_others_frames() {
    // A write request has a hex digit after the space; a response has a parameter letter.
    assert!(ok_responses(b"Wb 5*33\n").is_empty());
    assert!(ok_requests(b"Wb A*5c\n").is_empty());
    // A plain request has no space at all.
    assert!(ok_responses(b"T1*cf\n").is_empty());
    assert!(ok_requests(b"T1 A*27\n").is_empty());
}

#[test]
fn reset_forgets_a_partial_frame() {
    let mut decoder = RequestDecoder::new();
    for &b in b"T0*a" {
        assert_eq!(decoder.feed(b), None);
    }
    decoder.reset();
    let got: Vec<_> = b"Q0*ea\n".iter().filter_map(|&b| decoder.feed(b)).collect();
    assert_eq!(got, vec![Ok(Request::new(RequestCode::Query, 0))]);
}
