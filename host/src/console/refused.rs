//! Why a unit refused a register write, in the words the console (`set`) and `mmu printer`
//! (`write`, `settings load`) share: the register's range when the value is outside it, else the
//! guards' rule the unit names in register 0x8f (`mmu_firmware::guards`), with the other
//! threshold of a pair where that helps.

use mmu_firmware::guards::Rule;
use mmu_firmware::registers::{REFUSED_RULE, describe};

use super::names;

/// Why the unit refused `value` for register `address` (a unit of `slots` slots); `read` reads
/// a register of the unit (`None`: it could not).
pub fn why_refused(address: u8, value: u16, slots: u8, read: &mut dyn FnMut(u8) -> Option<u16>) -> String {
    let Some(register) = describe(address, usize::from(slots)) else {
        return format!("the unit has no register 0x{address:02x}");
    };
    match register.row.range() {
        None => "it is read only".to_string(),
        Some((low, high)) if value < low || value > high => {
            format!("{value} is out of its range, {low} to {high}")
        }
        Some(_) => broken_rule(address, slots, read),
    }
}

/// Why the unit refused an in-range write to `address`: the rule it names in register 0x8f.
fn broken_rule(address: u8, slots: u8, read: &mut dyn FnMut(u8) -> Option<u16>) -> String {
    let Some(rule) = read(REFUSED_RULE).and_then(Rule::from_code) else {
        return "the unit does not take that value here".to_string();
    };
    let mut partner = |address: u8| {
        let name = names::name(address, slots).unwrap_or_else(|| format!("0x{address:02x}"));
        match read(address) {
            Some(value) => format!("{name} is {value}"),
            None => format!("{name} could not be read"),
        }
    };
    let text = match (rule, address) {
        (Rule::ThresholdsOrdered, 0x90..=0x9f) => format!(
            "a sensor's \"on\" threshold must stay above its \"off\" one ({}): set \"off\" lower first",
            partner(address + 0x10)
        ),
        (Rule::ThresholdsOrdered, 0xa0..=0xaf) => format!(
            "a sensor's \"off\" threshold must stay below its \"on\" one ({}): set \"on\" higher first",
            partner(address - 0x10)
        ),
        (Rule::HysteresisAboveNoise, 0x90..=0x9f) => {
            format!("{} ({})", rule.meaning(), partner(address + 0x10))
        }
        (Rule::HysteresisAboveNoise, 0xa0..=0xaf) => {
            format!("{} ({})", rule.meaning(), partner(address - 0x10))
        }
        _ => rule.meaning().to_string(),
    };
    format!("rule {} ({}), {text}", rule.code(), rule.name())
}
