//! Human descriptions of requests and responses: code names, register names, progress and error
//! names with the printer's error screen. Used by `mmu decode`; meant to be shared by the other
//! host tools (simulator, printer emulator) for their logs.

mod errors;

use mmu_protocol::{
    ButtonCode, ErrorCode, ParamCode, ProgressCode, Request, RequestCode, Response, ResultCode,
};

pub use errors::error_help;

/// Register names of the MMU3 register map (spec §4), indexed by address 0x00..=0x23.
const REGISTER_NAMES: [&str; 36] = [
    "Project_Major",
    "Project_Minor",
    "Project_Revision",
    "Project_Build_Number",
    "MMU_Errors",
    "Current_Progress_Code",
    "Current_Error_Code",
    "Filament_State",
    "FINDA_State",
    "FSensor_State",
    "Motor_Mode",
    "Extra_Load_Distance",
    "FSensor_Unload_Check_Distance",
    "Pulley_Unload_Feedrate",
    "Pulley_Acceleration",
    "Selector_Acceleration",
    "Idler_Acceleration",
    "Pulley_Load_Feedrate",
    "Selector_Nominal_Feedrate",
    "Idler_Nominal_Feedrate",
    "Pulley_Slow_Feedrate",
    "Selector_Homing_Feedrate",
    "Idler_Homing_Feedrate",
    "Pulley_sg_thrs",
    "Selector_sg_thrs",
    "Idler_sg_thrs",
    "Get_Pulley_Position",
    "Selector_Slot",
    "Idler_Slot",
    "Selector_Cut_iRun",
    "Pulley_iRun",
    "Selector_iRun",
    "Idler_iRun",
    "Reserved_VCC",
    "Bowden_Length",
    "Cut_Length",
];

/// The name of register `address` in the MMU3 register map, if it exists.
pub fn register_name(address: u8) -> Option<&'static str> {
    REGISTER_NAMES.get(usize::from(address)).copied()
}

/// `register 0x08 FINDA_State` (the MMU3 name), `register 0x70 filtered.hub.filament` (this
/// unit's own), or `register 0x99 (no such register)`.
fn register_label(address: u8) -> String {
    let own = mmu_firmware::registers::describe(address, mmu_firmware::MAX_SLOTS);
    match (register_name(address), own) {
        (Some(name), _) => format!("register 0x{address:02x} {name}"),
        (None, Some(register)) => format!("register 0x{address:02x} {register}"),
        (None, None) => format!("register 0x{address:02x} (no such register)"),
    }
}

/// A note on a register value where the number alone says little.
fn register_value_note(address: u8, value: u16) -> Option<String> {
    use mmu_firmware::registers::{FAILURES, LANE, ODOMETRY, SENSOR_FAULTS, Subject, UNLOAD_STUCK};
    match address {
        0x05 => return u8::try_from(value).ok().map(|v| ProgressCode(v).to_string()),
        0x06 => return Some(ErrorCode(value).to_string()),
        0x07 => return Some(lane_state(value).to_string()),
        0x08 => return Some(finda_note(value).to_string()),
        0x0a => return Some(if value == 0 { "normal" } else { "stealth" }.to_string()),
        0x1b | 0x1c => return Some(slot_note(value)),
        SENSOR_FAULTS => return Some(stuck_sensors(value)),
        UNLOAD_STUCK => return Some(unload_stuck(value).to_string()),
        _ => {}
    }
    let register = mmu_firmware::registers::describe(address, mmu_firmware::MAX_SLOTS)?;
    match (register.row.address, register.subject) {
        (LANE, Some(Subject::Slot(_))) => Some(lane_state(value).to_string()),
        // Two's complement: a slot that pulled back more than it fed.
        (ODOMETRY, Some(Subject::Slot(_))) => Some(format!("{} mm", value as i16)),
        (FAILURES, Some(Subject::Slot(_))) if value > 0 => Some("errors while driving this slot".to_string()),
        _ => None,
    }
}

/// Why an unload stopped on `8004`, as register 0xfc says it.
pub fn unload_stuck(value: u16) -> &'static str {
    use mmu_firmware::phases::UnloadStuck;
    match value {
        v if v == UnloadStuck::InExtruder as u16 => {
            "the filament is held in the extruder: felt held and still (a blob on its tip, a cold nozzle, gears that still grip it)"
        }
        v if v == UnloadStuck::SensorStillOn as u16 => {
            "the filament came back freely its check distance, but the printer's sensor still reads it: the sensor sticks, a string of the tip is left at it, or the lane's drive slips"
        }
        _ => "no unload stopped on 8004, or the unit cannot tell why",
    }
}

/// The sensors a register 0x50 mask names as stuck at a supply rail.
fn stuck_sensors(mask: u16) -> String {
    if mask == 0 {
        return "no sensor stuck".to_string();
    }
    let stuck: Vec<String> = (0..16u8)
        .filter(|i| mask & (1 << i) != 0)
        .map(|i| {
            mmu_firmware::registers::describe(mmu_firmware::registers::RAW + i, mmu_firmware::MAX_SLOTS)
                .and_then(|r| r.subject)
                .map_or(format!("sensor {i}"), |subject| match subject {
                    mmu_firmware::registers::Subject::Sensor(sensor) => sensor.to_string(),
                    mmu_firmware::registers::Subject::Slot(slot) => format!("slot {slot}"),
                })
        })
        .collect();
    format!("stuck at a rail: {}", stuck.join(", "))
}

/// A register given by address (`0x22`, `34`) or by this unit's name (`bowden_mm`,
/// `filtered.hub.filament`).
pub fn parse_register(text: &str) -> Result<u8, String> {
    if text.starts_with(|c: char| c.is_ascii_digit()) {
        return crate::codec_cli::parse_u8(text);
    }
    mmu_firmware::registers::lookup(text, mmu_firmware::MAX_SLOTS).ok_or_else(|| {
        format!("{text:?} is no register: give an address (0x22) or a name such as bowden_mm or filtered.hub.filament")
    })
}

/// Where a slot's filament is, as register 0x07 and the lane registers 0xb8+k give it (MMU3
/// filament-state values, in this unit's words).
pub fn lane_state(value: u16) -> &'static str {
    match value {
        0 => "none or not known",
        1 => "parked",
        2 => "in the hub or the Bowden tube",
        4 => "at the printer's filament sensor",
        8 => "loaded",
        _ => "unknown state",
    }
}

/// A slot number as registers 0x1b and 0x1c give it: 5 means none, 255 not known.
fn slot_note(value: u16) -> String {
    match value {
        5 => "none".to_string(),
        255 => "unknown".to_string(),
        slot => format!("slot {slot}"),
    }
}

fn finda_note(value: u16) -> &'static str {
    if value == 0 {
        "no filament"
    } else {
        "filament present"
    }
}

/// The version part a `S<n>` request reads.
fn version_part(index: u8) -> Option<&'static str> {
    match index {
        0 => Some("major"),
        1 => Some("minor"),
        2 => Some("revision"),
        3 => Some("build"),
        _ => None,
    }
}

/// What `S<n>` reads: `version major`, or the register for n ≥ 4.
fn version_label(index: u8) -> String {
    match version_part(index) {
        Some(part) => format!("version {part}"),
        None => format!("version read of {}", register_label(index)),
    }
}

/// `button 1 Middle`.
fn button_label(value: u16) -> String {
    let name = u8::try_from(value)
        .ok()
        .and_then(|v| ButtonCode(v).name())
        .unwrap_or("unknown");
    format!("button {value} {name}")
}

/// The printer's `FilamentState` carried by `f<n>`.
fn filament_sensor_state(value: u8) -> &'static str {
    match value {
        0 => "not present",
        1 => "at fsensor",
        2 => "in nozzle",
        3 => "unavailable",
        _ => "unknown",
    }
}

/// A request as on the wire without its CRC, e.g. `T1` or `Wb 1e`.
pub fn request_label(request: &Request) -> String {
    without_crc(request.encode().as_str()).to_string()
}

/// A response as on the wire without its CRC, e.g. `T1 E8003` or `X0 F0`.
pub fn response_label(response: &Response) -> String {
    without_crc(response.encode().as_str()).to_string()
}

/// A frame's text up to its `*<crc>`.
fn without_crc(frame: &str) -> &str {
    frame.split_once('*').map_or(frame, |(body, _)| body)
}

/// An error code as a person reads it: `FSENSOR_DIDNT_SWITCH_ON (printer screen 04103)`.
pub fn error_meaning(error: ErrorCode) -> String {
    format!("{error} (printer screen {:05})", error.printer_screen())
}

/// What a request asks for, e.g. `tool change slot 1` or `write register 0x0b Extra_Load_Distance = 5`.
pub fn request_meaning(request: &Request) -> String {
    let v = request.value;
    match request.code {
        RequestCode::Query if v == 0 => "query".to_string(),
        RequestCode::Query => format!("query (value {v})"),
        RequestCode::Tool => format!("tool change slot {v}"),
        RequestCode::Load => format!("preload slot {v}"),
        RequestCode::Mode => match v {
            0 => "motor mode normal".to_string(),
            1 => "motor mode stealth".to_string(),
            _ => format!("motor mode {v}"),
        },
        RequestCode::Unload => "unload".to_string(),
        RequestCode::Reset => match v {
            0 => "reset".to_string(),
            42 => "erase EEPROM and reset".to_string(),
            _ => format!("reset (value {v}: soft reset)"),
        },
        RequestCode::Finda => "FINDA query".to_string(),
        RequestCode::Version => version_label(v),
        RequestCode::Button => format!("{} from the printer", button_label(v.into())),
        RequestCode::Eject => format!("eject slot {v}"),
        RequestCode::Write => format!("write {} = {}", register_label(v), request.value2),
        RequestCode::Cut => format!("cut slot {v}"),
        RequestCode::FilamentType => format!("filament type slot {v}"),
        RequestCode::FilamentSensor => {
            format!("filament sensor state {v} ({})", filament_sensor_state(v))
        }
        RequestCode::Home => "home".to_string(),
        RequestCode::Read => format!("read {}", register_label(v)),
    }
}

/// What a response says, e.g. `FSENSOR_DIDNT_SWITCH_ON (printer screen 04103)`,
/// `FeedingToFSensor` or `register 0x08 FINDA_State = 1 (filament present)`.
pub fn response_meaning(response: &Response) -> String {
    let pv = response.param_value;
    match (response.param, pv) {
        (ParamCode::Processing, Some(p)) => match u8::try_from(p) {
            Ok(p) => ProgressCode(p).to_string(),
            Err(_) => format!("UnknownProgress{p:x}"),
        },
        (ParamCode::Processing, None) => "processing (no progress code)".to_string(),
        (ParamCode::Error, Some(e)) => error_meaning(ErrorCode(e)),
        (ParamCode::Error, None) => "error (no error code)".to_string(),
        (ParamCode::Finished, Some(r)) => match ResultCode(r).name() {
            Some(name) => format!("finished {name}"),
            None => format!("finished, result {r}"),
        },
        (ParamCode::Finished, None) => "finished (no result printed)".to_string(),
        (ParamCode::Accepted, Some(value)) => accepted_value(response, value),
        (ParamCode::Accepted, None) => "accepted".to_string(),
        (ParamCode::Rejected, _) => "rejected".to_string(),
        (ParamCode::Button, Some(b)) => format!("{} pressed on the unit", button_label(b)),
        (ParamCode::Button, None) => "button (no number)".to_string(),
    }
}

/// An `A<value>`: the answer to a read.
fn accepted_value(response: &Response, value: u16) -> String {
    let address = response.value;
    match response.code {
        RequestCode::Version if version_part(address).is_some() => {
            format!("{} = {value}", version_label(address))
        }
        RequestCode::Version | RequestCode::Read => {
            let mut text = format!("{} = {value}", register_label(address));
            if let Some(note) = register_value_note(address, value) {
                text.push_str(&format!(" ({note})"));
            }
            text
        }
        RequestCode::Finda => format!("FINDA = {value} ({})", finda_note(value)),
        _ => format!("accepted, value {value}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn register_map_has_36_entries() {
        assert_eq!(register_name(0x08), Some("FINDA_State"));
        assert_eq!(register_name(0x22), Some("Bowden_Length"));
        assert_eq!(register_name(0x23), Some("Cut_Length"));
        assert_eq!(register_name(0x24), None);
    }

    #[test]
    fn meanings() {
        let t1 = Request::new(RequestCode::Tool, 1);
        assert_eq!(request_meaning(&t1), "tool change slot 1");
        assert_eq!(
            request_meaning(&Request::write(0x0b, 5)),
            "write register 0x0b Extra_Load_Distance = 5"
        );
        let e = Response::error(RequestCode::Tool, 0, ErrorCode(0x8003));
        assert_eq!(
            response_meaning(&e),
            "FSENSOR_DIDNT_SWITCH_ON (printer screen 04103)"
        );
        let r8 = Response::read(&Request::new(RequestCode::Read, 8), 1);
        assert_eq!(
            response_meaning(&r8),
            "register 0x08 FINDA_State = 1 (filament present)"
        );
        let s3 = Response::read(&Request::new(RequestCode::Version, 3), 896);
        assert_eq!(response_meaning(&s3), "version build = 896");
        assert_eq!(request_label(&Request::write(0x0b, 30)), "Wb 1e");
        assert_eq!(request_label(&t1), "T1");
        assert_eq!(response_label(&e), "T0 E8003");
    }
}
