//! The unit logic (placeholder).
#![no_std]
