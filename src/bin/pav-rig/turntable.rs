//! `pav-rig turntable`.

use crate::common::ctrl_c_flag;
use crate::port::{connect, parse_signed_seconds, PortArgs, SimTime};
use anyhow::{Context, Result};
use clap::Subcommand;
use std::time::Duration;
use turntable_proto::text::Milli;
use turntable_proto::Command;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    port: PortArgs,
    #[command(subcommand)]
    action: Action,
}

#[derive(Subcommand)]
enum Action {
    /// Print state, position and angle.
    #[command(after_help = "Examples:
  pav-rig turntable --port /dev/ttyACM0 status")]
    Status,
    /// Return to angle 0 and restart the turn count.
    #[command(after_help = "Examples:
  pav-rig turntable --port /dev/ttyACM0 home")]
    Home,
    /// Turn to an angle (degrees), or by an angle with --relative.
    #[command(after_help = "Examples:
  pav-rig turntable --port /dev/ttyACM0 rotate 90
  pav-rig turntable --port sim rotate --relative -- -45")]
    Rotate {
        /// Degrees.
        #[arg(allow_hyphen_values = true)]
        degrees: f64,
        /// Turn by DEGREES instead of to it.
        #[arg(long)]
        relative: bool,
    },
    /// Spin continuously; Ctrl-C stops the table.
    #[command(after_help = "Examples:
  pav-rig turntable --port /dev/ttyACM0 spin --period 28s --turns 1")]
    Spin {
        /// Seconds per revolution (negative: backwards).
        #[arg(long, default_value = "28s", value_parser = parse_signed_seconds, allow_hyphen_values = true)]
        period: f64,
        /// Revolutions (0 = until Ctrl-C).
        #[arg(long, default_value_t = 1)]
        turns: u32,
    },
    /// Ramp down to a halt.
    #[command(after_help = "Examples:
  pav-rig turntable --port /dev/ttyACM0 stop")]
    Stop,
    /// Emergency stop (locks until unlock).
    #[command(after_help = "Examples:
  pav-rig turntable --port /dev/ttyACM0 estop")]
    Estop,
    /// Clear an alarm.
    #[command(after_help = "Examples:
  pav-rig turntable --port /dev/ttyACM0 unlock")]
    Unlock,
}

fn milli(deg: f64) -> Result<Milli> {
    Milli::parse(&format!("{deg:.3}")).with_context(|| format!("{deg} is out of range"))
}

pub fn run(a: &Args) -> Result<()> {
    // The connection keeps a simulator alive as long as the table is used.
    let mut connected = connect(&a.port, SimTime::Real)?;
    let t = &mut connected.table;
    let motion = match a.action {
        Action::Status => {
            let st = t.status()?;
            let deg = t.degrees(st.pos);
            outln!(
                "state {:?}{}  position {} microsteps = {:.3}° ({:.3}° in the current turn)",
                st.state,
                st.alarm.map(|x| format!(" (alarm: {})", x.text())).unwrap_or_default(),
                st.pos,
                deg,
                deg.rem_euclid(360.0)
            );
            return Ok(());
        }
        Action::Stop => return Ok(t.command(Command::Stop).map(|_| ())?),
        Action::Unlock => return Ok(t.command(Command::Unlock).map(|_| ())?),
        Action::Estop => return Ok(t.estop()?),
        Action::Home => Command::Home,
        Action::Rotate { degrees, relative: false } => Command::MoveTo(milli(degrees)?),
        Action::Rotate { degrees, relative: true } => Command::MoveBy(milli(degrees)?),
        Action::Spin { period, turns } => Command::Spin { period_s: milli(period)?, turns },
    };
    let stop = ctrl_c_flag()?;
    let seq = t.start_motion(motion)?;
    // Angle reports arrive every 50 ms while moving; five silent seconds mean a dead link.
    let pos = t.wait_done_or_stop(seq, Duration::from_secs(5), &stop)?;
    outln!("done at {pos} microsteps = {:.3}°", t.degrees(pos));
    Ok(())
}
