//! What happens inside the simulator, as `mmu sim --events` writes it: one JSON object per line,
//! `{"t_ms":N,"kind":...}`. An external printer-side program follows the `fsensor` events to
//! report `f` as the printer would.

use serde::Serialize;

/// One thing that happened at a virtual time.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Event {
    /// Virtual time, ms since the simulator started.
    pub t_ms: u64,
    /// What happened.
    #[serde(flatten)]
    pub what: EventKind,
}

/// The kinds of [`Event`].
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum EventKind {
    /// The printer's filament sensor changed: 0 no filament, 1 at the sensor, 2 in the nozzle
    /// (the value of the `f` request).
    Fsensor {
        /// The new state.
        state: u8,
    },
    /// A slot's filament moved (reported at most every 100 ms while it moves, and when it stops).
    Slot {
        /// The slot.
        slot: usize,
        /// Filament tip, mm from the hub sensor (negative: before it); `null` without filament.
        tip_mm: Option<f32>,
    },
    /// A fault was injected or cleared.
    Fault {
        /// `inject` or `clear`.
        action: FaultAction,
        /// The fault, in `--fault` syntax.
        fault: String,
    },
    /// The unit lost power (`on: false`) or booted (`on: true`).
    Power {
        /// Powered.
        on: bool,
    },
    /// The unit's current command changed state.
    Command {
        /// The command as on the wire, e.g. `T1`.
        request: String,
        /// `running <progress>`, `error <code>` or `finished`.
        status: String,
    },
    /// A slot's motor command changed (every change, so external tools see all motion).
    Motor {
        /// The slot.
        slot: usize,
        /// `forward`, `reverse`, `brake` or `coast`.
        state: &'static str,
        /// Duty, per mille (0 unless driven).
        duty: u16,
    },
    /// The printer's extruder started a move of its own.
    Extruder {
        /// Why: `co-feed`, `extra-load`, `load-to-nozzle`, `unload-help`, `ramming`.
        action: &'static str,
        /// Distance, mm (negative: retract).
        mm: f32,
    },
}

/// Whether a fault came or went.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FaultAction {
    /// Injected.
    Inject,
    /// Cleared.
    Clear,
}

impl Event {
    /// The event as one line of JSON, without the newline.
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).unwrap_or_else(|_| String::from("{}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fsensor_event_is_the_documented_line() {
        let event = Event {
            t_ms: 1234,
            what: EventKind::Fsensor { state: 2 },
        };
        assert_eq!(event.to_json(), r#"{"t_ms":1234,"kind":"fsensor","state":2}"#);
    }
}
