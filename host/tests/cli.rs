//! End-to-end tests of the `mmu` binary: `encode` and `decode` as a user runs them.

use std::process::Output;

use serde_json::Value;

mod common;

use common::mmu_with_input as mmu;

fn stdout(output: &Output) -> String {
    String::from_utf8(output.stdout.clone()).expect("stdout is UTF-8")
}

fn stderr(output: &Output) -> String {
    String::from_utf8(output.stderr.clone()).expect("stderr is UTF-8")
}

/// `mmu encode args...` succeeds and prints exactly `expected` and a newline.
fn assert_encodes(args: &[&str], expected: &str) {
    let mut full = vec!["encode"];
    full.extend_from_slice(args);
    let output = mmu(&full, "");
    assert!(output.status.success(), "{args:?}: {}", stderr(&output));
    assert_eq!(stdout(&output), format!("{expected}\n"), "{args:?}");
    assert!(output.stderr.is_empty());
}

/// `mmu encode args...` fails with a non-zero exit code and says something on stderr.
fn assert_encode_fails(args: &[&str], message: &str) {
    let mut full = vec!["encode"];
    full.extend_from_slice(args);
    let output = mmu(&full, "");
    assert!(!output.status.success(), "{args:?} should fail");
    assert!(output.stdout.is_empty(), "{args:?} printed {:?}", stdout(&output));
    let err = stderr(&output);
    assert!(
        err.contains(message),
        "{args:?}: stderr {err:?} lacks {message:?}"
    );
}

/// The JSON objects `mmu decode --json` prints for `input`, one per input line.
fn decode_json(input: &str) -> Vec<Value> {
    let output = mmu(&["decode", "--json"], input);
    assert!(output.status.success(), "{}", stderr(&output));
    stdout(&output)
        .lines()
        .map(|line| serde_json::from_str(line).unwrap_or_else(|e| panic!("{line:?}: {e}")))
        .collect()
}

#[test]
fn encode_requests() {
    assert_encodes(&["request", "T", "1"], "T1*cf");
    assert_encodes(&["request", "Q", "0"], "Q0*ea");
    assert_encodes(&["request", "T", "4"], "T4*f");
    assert_encodes(&["request", "X", "42"], "X2a*88");
    assert_encodes(&["request", "X", "0x2a"], "X2a*88");
    assert_encodes(&["request", "f", "2"], "f2*f7");
    assert_encodes(&["request", "F", "0"], "F0*ef");
    assert_encodes(&["request", "R", "0x1b"], "R1b*9e");
    assert_encodes(&["request", "W", "0xb", "5"], "Wb 5*33");
    assert_encodes(&["request", "W", "11", "0x5"], "Wb 5*33");
    assert_encodes(&["request", "W", "0x22", "360"], "W22 168*51");
    assert_encodes(&["request", "W", "0xfd", "0x4c00"], "Wfd 4c00*80");
}

#[test]
fn encode_responses() {
    assert_encodes(&["response", "T", "0", "E", "0x8003"], "T0 E8003*13");
    assert_encodes(&["response", "T", "0", "E", "32771"], "T0 E8003*13");
    assert_encodes(&["response", "S", "0", "A", "3"], "S0 A3*22");
    assert_encodes(&["response", "S", "3", "A", "896"], "S3 A380*d9");
    assert_encodes(&["response", "W", "0x1b", "A"], "W1b A*c2");
    assert_encodes(&["response", "X", "0", "F", "0"], "X0 F0*87");
    assert_encodes(&["response", "X", "0", "F"], "X0 F*87");
    assert_encodes(&["response", "T", "0", "P", "0x1c"], "T0 P1c*6c");
    assert_encodes(&["response", "T", "1", "B", "1"], "T1 B1*8f");
    assert_encodes(&["response", "R", "0x99", "R"], "R99 R*c9");
}

#[test]
fn encode_rejects_bad_input() {
    assert_encode_fails(&["request", "Z", "1"], "unknown request code");
    assert_encode_fails(&["request", "t", "1"], "unknown request code");
    assert_encode_fails(&["request", "TT", "1"], "unknown request code");
    assert_encode_fails(&["request", "T", "256"], "too large");
    assert_encode_fails(&["request", "T", "0x100"], "too large");
    assert_encode_fails(&["request", "T", "abc"], "not a number");
    assert_encode_fails(&["request", "T", "-1"], "");
    assert_encode_fails(&["request", "T"], "VALUE");
    assert_encode_fails(&["request", "W", "0xb", "65536"], "too large");
    assert_encode_fails(&["request", "W", "0xb"], "needs VALUE2");
    assert_encode_fails(&["request", "T", "1", "2"], "only a write request");
    assert_encode_fails(&["response", "T", "0", "e", "1"], "unknown parameter code");
    assert_encode_fails(&["response", "T", "0", "X"], "unknown parameter code");
    assert_encode_fails(&["response", "T", "0", "E", "0x10000"], "too large");
    assert_encode_fails(&["response", "T", "0"], "PARAM");
    assert_encode_fails(&["frobnicate"], "");
}

#[test]
fn decode_human() {
    let input = "\
T0*a4
MMU2:>T1*cf.
MMU2:<T0 E8003*13.
Wb 5*33
Wb A*5c
T0 P1c*6c
T1 B1*8f
B1*dc
L0 F1*34
R8 A1*98
S3 A380*d9
f2*f7
";
    let output = mmu(&["decode"], input);
    assert!(output.status.success(), "{}", stderr(&output));
    let text = stdout(&output);
    let lines: Vec<_> = text.lines().collect();
    assert_eq!(
        lines,
        [
            "request T0 tool change slot 0, CRC ok",
            "request T1 tool change slot 1, CRC ok",
            "response T0 E8003 FSENSOR_DIDNT_SWITCH_ON (printer screen 04103), CRC ok",
            "request Wb 5 write register 0x0b Extra_Load_Distance = 5, CRC ok",
            "response Wb A accepted, CRC ok",
            "response T0 P1c FeedingToFSensor, CRC ok",
            "response T1 B1 button 1 Middle pressed on the unit, CRC ok",
            "request B1 button 1 Middle from the printer, CRC ok",
            "response L0 F1 finished Cancelled, CRC ok",
            "response R8 A1 register 0x08 FINDA_State = 1 (filament present), CRC ok",
            "response S3 A380 version build = 896, CRC ok",
            "request f2 filament sensor state 2 (in nozzle), CRC ok",
        ]
    );
}

#[test]
fn decode_bad_crc_and_invalid_lines_human() {
    let output = mmu(
        &["decode"],
        "T1*00\nX0 F0*86\nhello\n\nMMU2:Command rejected\nQ0*EA",
    );
    assert!(output.status.success(), "{}", stderr(&output));
    let text = stdout(&output);
    let lines: Vec<_> = text.lines().collect();
    assert_eq!(lines.len(), 6, "{text}");
    assert_eq!(
        lines[0],
        "request T1 tool change slot 1, CRC BAD (carries 0, expected cf)"
    );
    assert_eq!(
        lines[1],
        "response X0 F0 finished OK, CRC BAD (carries 86, expected 87)"
    );
    // Lines that are no frame are said to be so, with their text (before, the text was dropped:
    // the printer's "Command rejected" never showed); a broken frame is invalid.
    assert_eq!(lines[2], "not an MMU line: hello");
    assert_eq!(lines[3], "empty line");
    assert_eq!(lines[4], "the printer's MMU message: Command rejected");
    assert!(lines[5].starts_with("invalid: "), "{:?}", lines[5]);
}

#[test]
fn decode_json_request_and_response() {
    let objects = decode_json("MMU2:>T0*a4.\nMMU2:<T0 E8003*13.\nWb 5*33\nX0 F*87\nX0 F0*87\n");
    assert_eq!(objects.len(), 5);

    let t0 = &objects[0];
    assert_eq!(t0["kind"], "request");
    assert_eq!(t0["code"], "T");
    assert_eq!(t0["value"], 0);
    assert_eq!(t0["crc_ok"], true);
    assert_eq!(t0["meaning"], "tool change slot 0");
    assert!(t0.get("value2").is_none(), "value2 is for W only: {t0}");
    assert!(t0.get("param").is_none());

    let e = &objects[1];
    assert_eq!(e["kind"], "response");
    assert_eq!(e["code"], "T");
    assert_eq!(e["value"], 0);
    assert_eq!(e["param"], "E");
    assert_eq!(e["param_value"], 0x8003);
    assert_eq!(e["crc_ok"], true);
    assert_eq!(e["meaning"], "FSENSOR_DIDNT_SWITCH_ON (printer screen 04103)");

    let w = &objects[2];
    assert_eq!(w["kind"], "request");
    assert_eq!(w["code"], "W");
    assert_eq!(w["value"], 0x0b);
    assert_eq!(w["value2"], 5);
    assert_eq!(w["crc_ok"], true);

    // `param_value` only when the wire carries one.
    let bare = &objects[3];
    assert_eq!(bare["kind"], "response");
    assert_eq!(bare["param"], "F");
    assert!(bare.get("param_value").is_none(), "{bare}");
    assert_eq!(bare["crc_ok"], true);
    assert_eq!(objects[4]["param_value"], 0);
    assert_eq!(objects[4]["crc_ok"], true);
}

#[test]
fn decode_json_bad_crc_keeps_fields() {
    let objects = decode_json("X0 F0*86\nT1*00\n");
    let rsp = &objects[0];
    assert_eq!(rsp["kind"], "response");
    assert_eq!(rsp["code"], "X");
    assert_eq!(rsp["value"], 0);
    assert_eq!(rsp["param"], "F");
    assert_eq!(rsp["param_value"], 0);
    assert_eq!(rsp["crc_ok"], false);
    assert_eq!(rsp["crc"], 0x86);
    assert_eq!(rsp["crc_expected"], 0x87);
    assert!(rsp["meaning"].is_string());

    let req = &objects[1];
    assert_eq!(req["kind"], "request");
    assert_eq!(req["code"], "T");
    assert_eq!(req["value"], 1);
    assert_eq!(req["crc_ok"], false);
}

#[test]
fn decode_json_invalid_lines() {
    let objects = decode_json("hello\n\nok\nQ0*EA\nMMU2:>.\n");
    assert_eq!(objects.len(), 5);
    let kinds: Vec<&str> = objects.iter().map(|o| o["kind"].as_str().unwrap_or("")).collect();
    assert_eq!(kinds, ["other", "other", "other", "invalid", "invalid"]);
    for object in &objects {
        assert!(
            object["reason"].as_str().is_some_and(|r| !r.is_empty()),
            "{object}"
        );
        assert!(object.get("code").is_none());
        assert!(object.get("crc_ok").is_none());
    }
    assert_eq!(objects[0]["input"], "hello");
}

#[test]
fn decode_one_line_out_per_line_in_even_for_binary_junk() {
    let input = "T0*a4\n\u{0}\u{7f}\u{1b}[2J\nS0 A3*22\r\n\u{fffd}\n";
    let output = mmu(&["decode"], input);
    assert!(output.status.success(), "{}", stderr(&output));
    let text = stdout(&output);
    assert_eq!(text.lines().count(), 4, "{text}");
    assert_eq!(
        text.lines().nth(2),
        Some("response S0 A3 version major = 3, CRC ok")
    );
}

/// Real logs keep each line's time: OctoPrint's serial.log, Repetier's log, the Arduino serial
/// monitor with timestamps; non-MMU lines are said to be so, not "invalid" for a made-up reason.
#[test]
fn decode_keeps_the_time_of_real_log_lines() {
    let log = "\
2026-11-22 10:00:00,123 - Send: N12 T1*38
2026-11-22 10:00:00,130 - Recv: echo:MMU2:>T1*cf.
2026-11-22 10:00:00,145 - Recv: echo:MMU2:<T1 A*27.
2026-11-22 10:00:01,010 - Recv: ok
10:00:02.500 : echo:MMU2:<T1 P1c*45.
10:00:03.123 -> MMU2:<R1b A5*29.
";
    let output = mmu(&["decode"], log);
    assert!(output.status.success(), "{}", stderr(&output));
    let text = stdout(&output);
    let lines: Vec<_> = text.lines().collect();
    assert_eq!(lines.len(), 6, "{text}");
    assert!(
        lines[0].starts_with("2026-11-22 10:00:00,123  not an MMU line"),
        "{text}"
    );
    assert!(
        lines[1].starts_with("2026-11-22 10:00:00,130  request T1 tool change slot 1"),
        "{text}"
    );
    assert!(
        lines[2].starts_with("2026-11-22 10:00:00,145  response T1 A"),
        "{text}"
    );
    assert_eq!(lines[3], "2026-11-22 10:00:01,010  not an MMU line: ok");
    assert_eq!(
        lines[0],
        "2026-11-22 10:00:00,123  not an MMU line (the host's G-code to the printer): N12 T1*38"
    );
    assert!(lines[4].starts_with("10:00:02.500  response T1 P1c"), "{text}");
    assert!(lines[5].starts_with("10:00:03.123  response R1b A5"), "{text}");
    assert!(lines[5].contains("(none)"), "slot 5 means none: {text}");

    let objects = decode_json(log);
    assert_eq!(objects[1]["time"], "2026-11-22 10:00:00,130");
    assert_eq!(objects[1]["kind"], "request");
    assert_eq!(objects[0]["kind"], "other");
    assert_eq!(objects[3]["reason"], "not an MMU line");
    assert_eq!(objects[4]["time"], "10:00:02.500");

    let output = mmu(&["decode", "--frames-only"], log);
    let text = stdout(&output);
    assert_eq!(text.lines().count(), 4, "{text}");
    assert!(!text.contains("not an MMU line"), "{text}");
}

/// Values with a special meaning are named: slot 5 = none, 255 = unknown.
#[test]
fn decode_names_special_values() {
    let r1b = "R1b A5*29";
    let output = mmu(&["decode"], &format!("{r1b}\n"));
    let text = stdout(&output);
    assert!(
        text.lines().next().is_some_and(|l| l.contains("(none)")),
        "{text}"
    );
    let frame = mmu(&["encode", "response", "R", "0x1c", "A", "255"], "");
    let output = mmu(&["decode"], &stdout(&frame));
    assert!(stdout(&output).contains("(unknown)"), "{}", stdout(&output));
}

/// An error answer in a log carries what it means on this unit and what to check.
#[test]
fn decode_json_explains_errors() {
    let frame = mmu(&["encode", "response", "T", "1", "E", "0x8047"], "");
    let objects = decode_json(&stdout(&frame));
    let error = &objects[0];
    assert!(
        error["error_meaning"]
            .as_str()
            .is_some_and(|m| m.contains("slot motor")),
        "{error}"
    );
    assert!(
        error["check"].as_str().is_some_and(|c| c.contains("mmu sensors")),
        "{error}"
    );
}
