//! MCU entry point (placeholder until the board module lands).
#![no_std]
#![no_main]
