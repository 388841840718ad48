//! Turntable protocol core: line codec, commands, replies and integer-microstep motion.
//!
//! `no_std` and heap-free so the same logic runs in the RP2040 firmware, the QEMU firmware
//! used in tests and the host-side simulator. Conventions borrow from grbl, Marlin and Klipper:
//!
//! - One ASCII command per line. The host seals every line as `N<seq> <command>*XXXX`, where
//!   `XXXX` is the CRC-16 of everything before `*` in hex ([`frame`]); the device seals every
//!   line it sends the same way. A line with a sequence number must be sealed, and once a sealed
//!   line has been accepted the session is framed: bare or unsequenced lines are refused until a
//!   reset. Bare lines without `N` (a person at a terminal) work before that.
//! - Every line gets exactly one reply: `ok [N<seq>]` or `error:<code> [N<seq>] <message>`.
//!   Moves are acknowledged when accepted and report `done N<seq> pos=<usteps>` when finished.
//! - Real-time bytes bypass the line buffer: `!` (emergency stop), `?` (status), 0x18 (reset).
//! - On reset the device prints a banner with its firmware version and microsteps per turn.
//! - Alarms (stall, homing failure, emergency stop) lock motion until `UNLOCK`.
//! - Position is an integer count of microsteps, so no float drift builds up over turns.
//! - While moving, the device reports `@<t_ms> <usteps>` angle samples and sends
//!   `busy N<seq>` keep-alives during long moves.

#![no_std]
#![forbid(unsafe_code)]

pub mod codec;
pub mod command;
pub mod device;
pub mod frame;
pub mod motion;
pub mod reply;
pub mod text;

pub use codec::{Event, LineCodec, Realtime};
pub use command::{Command, Frame, ParseError, Received, SEQ_MODULUS};
pub use device::{Config, Device, Sink};
pub use motion::{Motion, Profile};
pub use reply::{Alarm, ErrorCode, Reply, State};

/// Protocol version printed in the banner. 2: CRC-16 seals both ways (1: a decimal XOR on
/// host lines only).
pub const PROTOCOL_VERSION: u32 = 2;

/// Longest command line accepted, excluding the terminator.
pub const MAX_LINE: usize = 96;

#[cfg(test)]
extern crate std;
