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

/// What an interrupted run left: its exit status code (`None`: ended by the signal itself), and
/// what it printed on stdout and stderr.
pub struct Interrupted {
    pub code: Option<i32>,
    pub stdout: String,
    pub stderr: String,
}

/// Start `command` (stdout and stderr piped, `input` on its stdin, which stays open), wait until
/// it printed `ready` (or, when a file is named, that file is not empty), let `after_ms`
/// pass, send Ctrl-C (SIGINT) and collect what it printed. Waiting for a sign of life first keeps
/// the signal from arriving before the program set up its Ctrl-C handling on a busy machine.
pub fn interrupt_when_ready(
    mut command: Command,
    input: Option<&str>,
    ready: &str,
    file: Option<&std::path::Path>,
    after_ms: u64,
) -> Interrupted {
    use std::io::Read;
    use std::sync::{Arc, Mutex};
    use std::time::{Duration, Instant};

    let stdin = if input.is_some() {
        Stdio::piped()
    } else {
        Stdio::null()
    };
    let mut child = command
        .stdin(stdin)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the command runs");
    // Kept open until the end: the program is still reading when Ctrl-C comes.
    let mut open_stdin = child.stdin.take();
    if let (Some(pipe), Some(text)) = (open_stdin.as_mut(), input) {
        pipe.write_all(text.as_bytes()).expect("the input goes in");
    }
    let collect = |mut pipe: Box<dyn Read + Send>| {
        let text = Arc::new(Mutex::new(Vec::new()));
        let sink = Arc::clone(&text);
        let reader = std::thread::spawn(move || {
            let mut buffer = [0u8; 4096];
            while let Ok(n) = pipe.read(&mut buffer) {
                if n == 0 {
                    break;
                }
                sink.lock().expect("not poisoned").extend_from_slice(&buffer[..n]);
            }
        });
        (text, reader)
    };
    let (stdout, out_reader) = collect(Box::new(child.stdout.take().expect("piped")));
    let (stderr, err_reader) = collect(Box::new(child.stderr.take().expect("piped")));
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let said = |pipe: &Arc<Mutex<Vec<u8>>>| {
            String::from_utf8_lossy(&pipe.lock().expect("not poisoned")).contains(ready)
        };
        let printed = said(&stdout) || said(&stderr);
        let written = file.is_some_and(|f| std::fs::metadata(f).is_ok_and(|m| m.len() > 0));
        let ended = child.try_wait().expect("waitable").is_some();
        if printed || written || ended || Instant::now() > deadline {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(after_ms));
    let _ = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status();
    let deadline = Instant::now() + Duration::from_secs(30);
    let status = loop {
        if let Some(status) = child.try_wait().expect("waitable") {
            break status;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("{command:?} did not end within 30 s of Ctrl-C");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    drop(open_stdin);
    let _ = out_reader.join();
    let _ = err_reader.join();
    let text = |pipe: &Arc<Mutex<Vec<u8>>>| {
        String::from_utf8_lossy(&pipe.lock().expect("not poisoned")).into_owned()
    };
    Interrupted {
        code: status.code(),
        stdout: text(&stdout),
        stderr: text(&stderr),
    }
}
