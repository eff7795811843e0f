//! SIGINT (Ctrl-C) and SIGTERM during a run: the first one asks the run to stop after the batch
//! of steps under way and the file being written, with a summary; a second one of the same
//! kind ends the process at once (what a stuck run needs), with the conventional exit code.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};

/// A signal that stops a run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StopSignal {
    Interrupt,
    Terminate,
}

impl StopSignal {
    pub fn name(self) -> &'static str {
        match self {
            StopSignal::Interrupt => "SIGINT",
            StopSignal::Terminate => "SIGTERM",
        }
    }

    /// 128 + the signal number, as a shell reports a process the signal ended.
    pub fn exit_code(self) -> i32 {
        match self {
            StopSignal::Interrupt => 130,
            StopSignal::Terminate => 143,
        }
    }
}

struct Flags {
    /// The last signal received (its number), 0 for none.
    received: Arc<AtomicUsize>,
}

static FLAGS: OnceLock<Option<Flags>> = OnceLock::new();

/// Installs the handlers (once; later calls do nothing). Where they cannot be installed the
/// signals keep their default action, with a warning.
pub fn install() {
    FLAGS.get_or_init(|| {
        let received = Arc::new(AtomicUsize::new(0));
        let installed = (|| -> std::io::Result<()> {
            for (signal, code) in [(signal_hook::consts::SIGINT, 130), (signal_hook::consts::SIGTERM, 143)] {
                let seen = Arc::new(AtomicBool::new(false));
                // Registered first, so it runs before `seen` is set: exits on the second signal.
                signal_hook::flag::register_conditional_shutdown(signal, code, seen.clone())?;
                signal_hook::flag::register(signal, seen)?;
                signal_hook::flag::register_usize(signal, received.clone(), signal as usize)?;
            }
            Ok(())
        })();
        match installed {
            Ok(()) => Some(Flags { received }),
            Err(e) => {
                eprintln!("warning: cannot handle Ctrl-C and SIGTERM ({e}); they will end the run without a summary");
                None
            }
        }
    });
}

/// The signal that asked the run to stop, if one did.
pub fn requested() -> Option<StopSignal> {
    let flags = FLAGS.get()?.as_ref()?;
    match flags.received.load(Ordering::SeqCst) {
        0 => None,
        s if s == signal_hook::consts::SIGTERM as usize => Some(StopSignal::Terminate),
        _ => Some(StopSignal::Interrupt),
    }
}
