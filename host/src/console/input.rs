//! Where the console's commands come from: a person at a terminal (line editing, history kept in
//! `~/.mmu_console_history`, tab completion of commands and register names, with rustyline), or a
//! script on a pipe, one command a line.

use std::io::{BufRead, IsTerminal};
use std::path::PathBuf;
use std::sync::mpsc::{self, Receiver};

use rustyline::completion::Completer;
use rustyline::highlight::Highlighter;
use rustyline::hint::Hinter;
use rustyline::history::DefaultHistory;
use rustyline::validate::Validator;
use rustyline::{Context, Editor, Helper};

use super::commands::WORDS;
use super::names;

/// Second words completion offers after a first word.
fn second_words(first: &str, slots: u8) -> Vec<String> {
    match first {
        "read" | "r" | "set" | "write" | "w" => names::all(slots),
        "fsensor" | "f" => ["on", "off", "auto"].map(String::from).to_vec(),
        "calibrate" => ["all", "mm-per-rev", "bowden", "thresholds", "park"]
            .map(String::from)
            .to_vec(),
        "sim" => ["fault", "clear"].map(String::from).to_vec(),
        _ => Vec::new(),
    }
}

/// Tab completion of the console's words.
pub struct Words {
    slots: u8,
}

impl Completer for Words {
    type Candidate = String;

    fn complete(&self, line: &str, pos: usize, _: &Context<'_>) -> rustyline::Result<(usize, Vec<String>)> {
        let before = line.get(..pos).unwrap_or(line);
        let start = before.rfind(' ').map_or(0, |i| i + 1);
        let word = before.get(start..).unwrap_or("");
        let earlier: Vec<&str> = before.get(..start).unwrap_or("").split_whitespace().collect();
        let choices = match earlier.as_slice() {
            [] => WORDS.iter().map(|w| w.to_string()).collect(),
            [first] => second_words(first, self.slots),
            _ => Vec::new(),
        };
        let matching = choices.into_iter().filter(|c| c.starts_with(word)).collect();
        Ok((start, matching))
    }
}

impl Hinter for Words {
    type Hint = String;
}
impl Highlighter for Words {}
impl Validator for Words {}
impl Helper for Words {}

/// The source of command lines.
pub enum Input {
    /// A person at a terminal.
    Terminal(Box<Editor<Words, DefaultHistory>>),
    /// A script on a pipe; each line is echoed so the transcript reads like a session.
    Script,
    /// Fixed answers (tests).
    #[cfg(test)]
    Lines(std::collections::VecDeque<String>),
}

impl Input {
    /// A terminal's editor when stdin is one (tab completes register names of `slots` slots),
    /// else the script on stdin.
    pub fn from_stdin(slots: u8) -> Input {
        if !std::io::stdin().is_terminal() {
            return Input::Script;
        }
        match Editor::<Words, DefaultHistory>::new() {
            Ok(mut editor) => {
                editor.set_helper(Some(Words { slots }));
                if let Some(path) = history_path() {
                    let _ = editor.load_history(&path);
                }
                Input::Terminal(Box::new(editor))
            }
            Err(_) => Input::Script,
        }
    }

    /// True for a script on a pipe.
    pub fn is_script(&self) -> bool {
        !matches!(self, Input::Terminal(_))
    }

    /// The next line, after `prompt` on a terminal; `None` at the end of the input (Ctrl-D).
    pub fn line(&mut self, prompt: &str) -> Option<String> {
        match self {
            Input::Terminal(editor) => match editor.readline(prompt) {
                Ok(line) => {
                    if !line.trim().is_empty() {
                        let _ = editor.add_history_entry(line.as_str());
                        if let Some(path) = history_path() {
                            let _ = editor.save_history(&path);
                        }
                    }
                    Some(line)
                }
                // Ctrl-C on an empty line ends the session too.
                Err(_) => None,
            },
            #[cfg(test)]
            Input::Lines(lines) => lines.pop_front(),
            Input::Script => {
                let mut line = String::new();
                match std::io::stdin().lock().read_line(&mut line) {
                    Ok(0) | Err(_) => None,
                    Ok(_) => {
                        let line = line.trim_end().to_string();
                        println!("{prompt}{line}");
                        Some(line)
                    }
                }
            }
        }
    }

    /// A line (an Enter press, or the script's next line) arriving while the unit works: read on
    /// a thread, so the caller keeps polling the unit.
    pub fn watch_enter(&self) -> Receiver<String> {
        let (sender, receiver) = mpsc::channel();
        std::thread::spawn(move || {
            let mut line = String::new();
            if std::io::stdin().lock().read_line(&mut line).is_ok_and(|n| n > 0) {
                let _ = sender.send(line.trim_end().to_string());
            }
        });
        receiver
    }
}

fn history_path() -> Option<PathBuf> {
    std::env::var_os("HOME").map(|home| PathBuf::from(home).join(".mmu_console_history"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn complete(line: &str) -> (usize, Vec<String>) {
        let history = DefaultHistory::new();
        let context = Context::new(&history);
        Words { slots: 3 }.complete(line, line.len(), &context).unwrap()
    }

    #[test]
    fn completes_commands_and_register_names() {
        assert_eq!(complete("unl"), (0, vec!["unload".to_string()]));
        let (start, names) = complete("read hub.");
        assert_eq!(start, 5);
        assert!(names.contains(&"hub.filament".to_string()), "{names:?}");
        let (_, names) = complete("set bow");
        assert_eq!(names, ["bowden_mm", "bowden_slowdown_mm"]);
        assert_eq!(complete("fsensor o").1, ["on", "off"]);
    }
}
