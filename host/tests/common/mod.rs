//! Running the `mmu` binary as a user does, shared by the host tool's end-to-end tests.

#![allow(dead_code)] // each test file uses a different part

use std::io::Write;
use std::process::{Child, Command, Output, Stdio};

/// `mmu ARGS`, run to its end.
pub fn mmu(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mmu"))
        .args(args)
        .output()
        .expect("the mmu binary runs")
}

/// `mmu ARGS` started with stdin, stdout and stderr piped.
pub fn spawn_mmu(args: &[&str]) -> Child {
    Command::new(env!("CARGO_BIN_EXE_mmu"))
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the mmu binary runs")
}

/// `mmu ARGS` with `input` on its stdin, run to its end.
pub fn mmu_with_input(args: &[&str], input: &str) -> Output {
    let mut child = spawn_mmu(args);
    child
        .stdin
        .take()
        .expect("stdin is piped")
        .write_all(input.as_bytes())
        .expect("stdin takes the input");
    child.wait_with_output().expect("mmu ends")
}

/// What a run printed, stdout then stderr.
pub fn text(output: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    )
}
