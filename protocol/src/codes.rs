//! The protocol's code tables: request and parameter letters, MMU3 error and progress codes,
//! `F` result codes and button numbers.
//!
//! Numeric tables are newtypes over the wire value, so a code this library does not name (a newer
//! firmware's, or a TMC bit combination) is kept as it came and still encodes the same.

use core::fmt;

macro_rules! letter_enum {
    ($(#[$meta:meta])* $name:ident { $($(#[$vmeta:meta])* $variant:ident = $byte:literal,)* }) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        #[repr(u8)]
        pub enum $name {
            $($(#[$vmeta])* $variant = $byte,)*
        }

        impl $name {
            /// Every code, in table order.
            pub const ALL: &'static [$name] = &[$($name::$variant,)*];

            /// The code for an ASCII letter (case-sensitive).
            pub const fn from_byte(byte: u8) -> Option<Self> {
                match byte {
                    $($byte => Some($name::$variant),)*
                    _ => None,
                }
            }

            /// The ASCII letter on the wire.
            pub const fn as_byte(self) -> u8 {
                self as u8
            }

            /// The letter as a `char`.
            pub const fn as_char(self) -> char {
                self as u8 as char
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "{}", self.as_char())
            }
        }
    };
}

letter_enum! {
    /// The first letter of a request: what the printer asks (Prusa `RequestMsgCodes`).
    RequestCode {
        /// `Q`: report the current command's state (the heartbeat).
        Query = b'Q',
        /// `T<slot>`: tool change.
        Tool = b'T',
        /// `L<slot>`: preload a slot up to the unit.
        Load = b'L',
        /// `M<mode>`: motor mode (0 normal, 1 stealth); MMU 3.0.3 does not answer it.
        Mode = b'M',
        /// `U0`: unload the filament from the nozzle.
        Unload = b'U',
        /// `X0` reset, `X42` erase persisted data then reset; never answered.
        Reset = b'X',
        /// `P0`: read the FINDA (here: the hub filament sensor).
        Finda = b'P',
        /// `S<n>`: version part n (a read of register n).
        Version = b'S',
        /// `B<n>`: a button pressed on the printer's screen.
        Button = b'B',
        /// `E<slot>`: eject the filament of a slot.
        Eject = b'E',
        /// `W<addr> <value>`: write a register.
        Write = b'W',
        /// `K<slot>`: cut the filament.
        Cut = b'K',
        /// `F<slot>`: filament type; never answered.
        FilamentType = b'F',
        /// `f<state>`: the printer's filament sensor state.
        FilamentSensor = b'f',
        /// `H<mode>`: home.
        Home = b'H',
        /// `R<addr>`: read a register.
        Read = b'R',
    }
}

impl RequestCode {
    /// True for the codes that start a command (answered `A` or `R`, then reported by `Q0`).
    pub const fn is_command(self) -> bool {
        matches!(
            self,
            RequestCode::Tool
                | RequestCode::Load
                | RequestCode::Unload
                | RequestCode::Eject
                | RequestCode::Cut
                | RequestCode::Home
        )
    }

    /// A name for people reading logs.
    pub const fn name(self) -> &'static str {
        match self {
            RequestCode::Query => "query",
            RequestCode::Tool => "tool change",
            RequestCode::Load => "preload",
            RequestCode::Mode => "motor mode",
            RequestCode::Unload => "unload",
            RequestCode::Reset => "reset",
            RequestCode::Finda => "FINDA query",
            RequestCode::Version => "version",
            RequestCode::Button => "button",
            RequestCode::Eject => "eject",
            RequestCode::Write => "write register",
            RequestCode::Cut => "cut",
            RequestCode::FilamentType => "filament type",
            RequestCode::FilamentSensor => "filament sensor",
            RequestCode::Home => "home",
            RequestCode::Read => "read register",
        }
    }
}

letter_enum! {
    /// The parameter letter of a response (Prusa `ResponseMsgParamCodes`).
    ParamCode {
        /// `P<progress>`: the command is running.
        Processing = b'P',
        /// `E<error>`: the command stopped and waits for the user.
        Error = b'E',
        /// `F<result>`: the command finished.
        Finished = b'F',
        /// `A[value]`: accepted (with the value of a read).
        Accepted = b'A',
        /// `R`: rejected.
        Rejected = b'R',
        /// `B<button>`: a button pressed on the unit, for the printer to handle.
        Button = b'B',
    }
}

impl ParamCode {
    /// A name for people reading logs.
    pub const fn name(self) -> &'static str {
        match self {
            ParamCode::Processing => "processing",
            ParamCode::Error => "error",
            ParamCode::Finished => "finished",
            ParamCode::Accepted => "accepted",
            ParamCode::Rejected => "rejected",
            ParamCode::Button => "button",
        }
    }
}

/// An MMU3 error code (`E<code>`, register 0x06), as in Prusa's `error_codes.h`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ErrorCode(pub u16);

/// The name printed for a code: Prusa's, where it differs from the Rust constant's.
macro_rules! label {
    ($name:ident) => {
        stringify!($name)
    };
    ($name:ident $label:literal) => {
        $label
    };
}

macro_rules! named_codes {
    ($ty:ident($int:ty) { $($(#[$meta:meta])* $name:ident = $value:literal $(=> $label:literal)?,)* }) => {
        impl $ty {
            $($(#[$meta])* pub const $name: $ty = $ty($value);)*

            /// Every named code, in table order.
            pub const NAMED: &'static [$ty] = &[$($ty::$name,)*];

            /// The name in Prusa's table, if this value has one.
            pub const fn name(self) -> Option<&'static str> {
                match self.0 {
                    $($value => Some(label!($name $($label)?)),)*
                    _ => None,
                }
            }

            /// The raw value on the wire.
            pub const fn value(self) -> $int {
                self.0
            }
        }
    };
}

named_codes! {
    ErrorCode(u16) {
        /// The command is still running (never sent as `E`).
        RUNNING = 0x0000,
        /// The command finished (never sent as `E`).
        OK = 0x0001,
        /// Axis bit: the pulley (here: the slot motor).
        TMC_PULLEY_BIT = 0x0040,
        /// Axis bit: the selector.
        TMC_SELECTOR_BIT = 0x0080,
        /// Axis bit: the idler.
        TMC_IDLER_BIT = 0x0100,
        /// The FINDA (here: the hub sensor) did not see the filament arrive.
        FINDA_DIDNT_SWITCH_ON = 0x8001,
        /// The FINDA (here: the hub sensor) still sees filament that should have left.
        FINDA_DIDNT_SWITCH_OFF = 0x8002,
        /// The printer's filament sensor did not trigger while loading.
        FSENSOR_DIDNT_SWITCH_ON = 0x8003,
        /// The printer's filament sensor did not clear while unloading.
        FSENSOR_DIDNT_SWITCH_OFF = 0x8004,
        /// Filament already loaded.
        FILAMENT_ALREADY_LOADED = 0x8005,
        /// The slot does not exist on this unit.
        INVALID_TOOL = 0x8006,
        /// Homing failed (always with an axis bit).
        HOMING_FAILED = 0x8007,
        /// Stored state and sensors disagree: unload manually.
        FINDA_VS_EEPROM_DISREPANCY = 0x8008,
        /// The printer's filament sensor triggered too early.
        FSENSOR_TOO_EARLY = 0x8009,
        /// The FINDA flickers.
        FINDA_FLICKERS = 0x800a,
        /// A move failed (always with an axis bit).
        MOVE_FAILED = 0x800b,
        /// The filament was ejected; waiting for the user's Continue.
        FILAMENT_EJECTED = 0x800c,
        /// The MCU supply is too low.
        MCU_UNDERVOLTAGE_VCC = 0x800d,
        /// The pulley stalled (here: the slot motor turns no more).
        STALLED_PULLEY = 0x8047,
        /// A pulley move failed (here: the slot motor reports no revolutions).
        MOVE_PULLEY_FAILED = 0x804b,
        /// The selector could not home.
        HOMING_SELECTOR_FAILED = 0x8087,
        /// The selector could not move.
        MOVE_SELECTOR_FAILED = 0x808b,
        /// The idler could not home.
        HOMING_IDLER_FAILED = 0x8107,
        /// The idler could not move.
        MOVE_IDLER_FAILED = 0x810b,
        /// Printer side: a load to the nozzle failed.
        FILAMENT_CHANGE = 0x8029,
        /// Printer side: loading to the extruder failed.
        LOAD_TO_EXTRUDER_FAILED = 0x802a,
        /// Printer side: the queue was full.
        QUEUE_FULL = 0x802b,
        /// Printer side: the unit reports a version the printer does not support.
        VERSION_MISMATCH = 0x802c,
        /// Printer side: the link is garbled.
        PROTOCOL_ERROR = 0x802d,
        /// Printer side: the unit does not answer.
        MMU_NOT_RESPONDING = 0x802e,
        /// An internal runtime error.
        INTERNAL = 0x802f,
        /// Driver I/O mismatch (with axis bits).
        TMC_IOIN_MISMATCH = 0x8200,
        /// Driver reset (with axis bits).
        TMC_RESET = 0x8400,
        /// Driver charge-pump undervoltage (with axis bits).
        TMC_UNDERVOLTAGE_ON_CHARGE_PUMP = 0x8800,
        /// Driver output short to ground (with axis bits).
        TMC_SHORT_TO_GROUND = 0x9000,
        /// Driver over-temperature warning (with axis bits).
        TMC_OVER_TEMPERATURE_WARN = 0xa000,
        /// Driver over-temperature error (with axis bits).
        TMC_OVER_TEMPERATURE_ERROR = 0xc000,
        /// Unreliable driver I/O: hardware needs attention (with axis bits).
        MMU_SOLDERING_NEEDS_ATTENTION = 0xc200,
    }
}

impl ErrorCode {
    /// The error screen a Buddy printer (MK4, MK3.5, Core One) shows for this code (`04103` is printed
    /// as 4103), 4900 (unknown error) when it has none. Other families and the buttons:
    /// [`crate::screens`].
    pub const fn printer_screen(self) -> u16 {
        crate::screens::screen_id(self, crate::screens::Family::Buddy)
    }
}

impl fmt::Display for ErrorCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.name() {
            Some(name) => f.write_str(name),
            None => write!(f, "UNKNOWN_ERROR_{:x}", self.0),
        }
    }
}

/// An MMU3 progress code (`P<code>`, register 0x05), as in Prusa's `progress_codes.h`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ProgressCode(pub u8);

named_codes! {
    ProgressCode(u8) {
        /// No operation in progress.
        OK = 0,
        /// Engaging the idler (here: engaging the slot motor).
        ENGAGING_IDLER = 1 => "EngagingIdler",
        /// Disengaging the idler (here: releasing the slot motor).
        DISENGAGING_IDLER = 2 => "DisengagingIdler",
        /// Pulling the filament back until the FINDA (hub sensor) clears. The printer retracts with it.
        UNLOADING_TO_FINDA = 3 => "UnloadingToFinda",
        /// Unloading to the pulley.
        UNLOADING_TO_PULLEY = 4 => "UnloadingToPulley",
        /// Feeding until the FINDA (hub sensor) sees the filament.
        FEEDING_TO_FINDA = 5 => "FeedingToFinda",
        /// Feeding fast through the Bowden tube.
        FEEDING_TO_BONDTECH = 6 => "FeedingToBondtech",
        /// Pushing the extra load distance into the nozzle.
        FEEDING_TO_NOZZLE = 7 => "FeedingToNozzle",
        /// Avoiding grind.
        AVOIDING_GRIND = 8 => "AvoidingGrind",
        /// Finishing moves.
        FINISHING_MOVES = 9 => "FinishingMoves",
        /// Stopping before an error is reported.
        ERR_DISENGAGING_IDLER = 10 => "ERRDisengagingIdler",
        /// Engaging after an error.
        ERR_ENGAGING_IDLER = 11 => "ERREngagingIdler",
        /// Waiting for the user (reported on the wire as `E<code>`).
        ERR_WAITING_FOR_USER = 12 => "ERRWaitingForUser",
        /// Internal error.
        ERR_INTERNAL = 13 => "ERRInternal",
        /// Helping the filament after an error.
        ERR_HELPING_FILAMENT = 14 => "ERRHelpingFilament",
        /// Driver failure.
        ERR_TMC_FAILED = 15 => "ERRTMCFailed",
        /// Unloading filament.
        UNLOADING_FILAMENT = 16 => "UnloadingFilament",
        /// Loading filament.
        LOADING_FILAMENT = 17 => "LoadingFilament",
        /// Selecting the filament slot.
        SELECTING_FILAMENT_SLOT = 18 => "SelectingFilamentSlot",
        /// Preparing the blade.
        PREPARING_BLADE = 19 => "PreparingBlade",
        /// Pushing the filament.
        PUSHING_FILAMENT = 20 => "PushingFilament",
        /// Performing the cut.
        PERFORMING_CUT = 21 => "PerformingCut",
        /// Returning the selector.
        RETURNING_SELECTOR = 22 => "ReturningSelector",
        /// Parking the selector.
        PARKING_SELECTOR = 23 => "ParkingSelector",
        /// Ejecting the filament.
        EJECTING_FILAMENT = 24 => "EjectingFilament",
        /// Retracting from the FINDA (hub sensor) to the park position.
        RETRACTING_FROM_FINDA = 25 => "RetractingFromFinda",
        /// Homing (here: checking the sensors).
        HOMING = 26 => "Homing",
        /// Moving the selector.
        MOVING_SELECTOR = 27 => "MovingSelector",
        /// Feeding slowly until the printer's filament sensor triggers. The printer co-feeds.
        FEEDING_TO_FSENSOR = 28 => "FeedingToFSensor",
        /// Hardware test: begin.
        HW_TEST_BEGIN = 29 => "HWTestBegin",
        /// Hardware test: idler.
        HW_TEST_IDLER = 30 => "HWTestIdler",
        /// Hardware test: selector.
        HW_TEST_SELECTOR = 31 => "HWTestSelector",
        /// Hardware test: pulley.
        HW_TEST_PULLEY = 32 => "HWTestPulley",
        /// Hardware test: cleanup.
        HW_TEST_CLEANUP = 33 => "HWTestCleanup",
        /// Hardware test: exec.
        HW_TEST_EXEC = 34 => "HWTestExec",
        /// Hardware test: display.
        HW_TEST_DISPLAY = 35 => "HWTestDisplay",
        /// Hardware test failed.
        ERR_HW_TEST_FAILED = 36 => "ErrHwTestFailed",
        /// Empty.
        EMPTY = 255 => "Empty",
    }
}

impl fmt::Display for ProgressCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.name() {
            Some(name) => f.write_str(name),
            None => write!(f, "UnknownProgress{:x}", self.0),
        }
    }
}

/// The result carried by `F<result>` (Prusa `ResultCode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ResultCode(pub u16);

named_codes! {
    ResultCode(u16) {
        /// Finished as asked.
        OK = 0,
        /// Cancelled (only a preload can be).
        CANCELLED = 1 => "Cancelled",
    }
}

/// A button number, in both directions (`B<n>` request and `B<n>` response parameter).
///
/// Which screen button a printer sends as which number depends on the screen and the printer family
/// ([`crate::screens`]): Retry is always `B1`, but FIL. ALREADY LOADED's Unload is `B0` from a Buddy
/// printer and `B2` from an MK3S, whose Continue there is `B0`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ButtonCode(pub u8);

named_codes! {
    ButtonCode(u8) {
        /// Right.
        RIGHT = 0 => "Right",
        /// Middle: Retry, and Continue/Done on single-button screens (the only one MMU 3.0.3 acts on).
        MIDDLE = 1 => "Middle",
        /// Left.
        LEFT = 2 => "Left",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn letters_round_trip() {
        for &code in RequestCode::ALL {
            assert_eq!(RequestCode::from_byte(code.as_byte()), Some(code));
        }
        for &code in ParamCode::ALL {
            assert_eq!(ParamCode::from_byte(code.as_byte()), Some(code));
        }
        assert_eq!(RequestCode::ALL.len(), 16);
        assert_eq!(RequestCode::from_byte(b'q'), None);
        assert_eq!(RequestCode::from_byte(b'f'), Some(RequestCode::FilamentSensor));
        assert_eq!(RequestCode::from_byte(b'F'), Some(RequestCode::FilamentType));
    }

    #[test]
    fn named_errors_and_their_screens() {
        assert_eq!(ErrorCode(0x8003).name(), Some("FSENSOR_DIDNT_SWITCH_ON"));
        assert_eq!(ErrorCode::FSENSOR_DIDNT_SWITCH_ON.printer_screen(), 4103);
        assert_eq!(ErrorCode::FILAMENT_EJECTED.printer_screen(), 4507);
        assert_eq!(ErrorCode::STALLED_PULLEY.printer_screen(), 4105);
        assert_eq!(ErrorCode::MOVE_PULLEY_FAILED.printer_screen(), 4105);
        assert_eq!(ErrorCode::FINDA_VS_EEPROM_DISREPANCY.printer_screen(), 4506);
        assert_eq!(ErrorCode(0x1234).name(), None);
        assert_eq!(ErrorCode(0x1234).printer_screen(), 4900);
    }

    #[test]
    fn tmc_codes_pick_driver_and_flag_as_the_printer_does() {
        assert_eq!(ErrorCode(0x8240).printer_screen(), 4301);
        assert_eq!(ErrorCode(0x8280).printer_screen(), 4311);
        assert_eq!(ErrorCode(0x8300).printer_screen(), 4321);
        assert_eq!(ErrorCode(0xa040).printer_screen(), 4201);
        assert_eq!(ErrorCode(0xc2c0).printer_screen(), 4305);
        assert_eq!(ErrorCode(0x8200).printer_screen(), 4900);
    }

    #[test]
    fn unknown_values_are_kept() {
        assert_eq!(ErrorCode(0x8fff).value(), 0x8fff);
        assert_eq!(ProgressCode(0x99).value(), 0x99);
        assert_eq!(ProgressCode(0x1c).name(), Some("FeedingToFSensor"));
        use std::string::ToString;
        assert_eq!(ErrorCode(0x8fff).to_string(), "UNKNOWN_ERROR_8fff");
    }
}
