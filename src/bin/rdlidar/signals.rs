//! Ctrl-C (SIGINT) and termination requests (SIGTERM, which `mpirun` sends every process of a
//! job it stops, a second before SIGKILL): a thread of their own receives them, so that a
//! command can stop at a point of its choosing or clean up before quitting, and tell one from
//! the other.

/// A signal that asks the process to stop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Signal {
    /// SIGINT: Ctrl-C.
    Interrupt,
    /// SIGTERM: `kill`, a batch system or `mpirun` ending the job.
    Terminate,
}

impl Signal {
    /// The exit status of a process that quits on it: 128 + its number, as a shell reports a
    /// process ended by the signal (130, 143).
    pub fn exit_code(self) -> i32 {
        match self {
            Signal::Interrupt => 130,
            Signal::Terminate => 143,
        }
    }
}

/// Calls `handler` on a thread of its own with every SIGINT and SIGTERM the process receives,
/// in place of their default action (ending the process at once). To be called once per
/// process; where signals cannot be handled (not Unix), does nothing.
///
/// # Errors
/// A message when the pipe, the thread or a handler cannot be set up.
pub fn handle(handler: impl FnMut(Signal) + Send + 'static) -> Result<(), String> {
    #[cfg(unix)]
    {
        install(handler).map_err(|e| format!("cannot handle Ctrl-C: {e}"))
    }
    #[cfg(not(unix))]
    {
        let _ = handler;
        Ok(())
    }
}

#[cfg(unix)]
fn install(mut handler: impl FnMut(Signal) + Send + 'static) -> std::io::Result<()> {
    use signal_hook::consts::signal::{SIGINT, SIGTERM};
    let mut signals = signal_hook::iterator::Signals::new([SIGINT, SIGTERM])?;
    std::thread::Builder::new()
        .name("signals".into())
        .spawn(move || {
            for signal in &mut signals {
                match signal {
                    SIGINT => handler(Signal::Interrupt),
                    SIGTERM => handler(Signal::Terminate),
                    _ => {}
                }
            }
        })?;
    Ok(())
}
