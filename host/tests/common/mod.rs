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

/// The user's documentation: the README and every page of the book (`book/src/**/*.md`), each
/// with its path relative to the repository's root, in a stable order.
pub fn documentation() -> Vec<(String, String)> {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut pages = vec!["README.md".to_string()];
    let mut folders = vec![root.join("book/src")];
    while let Some(folder) = folders.pop() {
        let entries = std::fs::read_dir(&folder).expect("the book's folder is readable");
        for entry in entries {
            let path = entry.expect("a book entry is readable").path();
            if path.is_dir() {
                folders.push(path);
            } else if path.extension().is_some_and(|ext| ext == "md") {
                let relative = path.strip_prefix(&root).expect("under the root");
                pages.push(relative.to_string_lossy().into_owned());
            }
        }
    }
    pages.sort();
    pages
        .into_iter()
        .map(|page| {
            let text = std::fs::read_to_string(root.join(&page))
                .unwrap_or_else(|e| panic!("{page} is readable: {e}"));
            (page, text)
        })
        .collect()
}
