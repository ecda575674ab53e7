//! Threads for work that may wait: building a match, re-simulating a replay, an export.
//! They run at a lower scheduling priority than the async workers and the match tasks, so
//! on a machine whose cores they fill the live matches keep their ticks and requests their
//! answers; they take what is left.

use std::io;
use std::thread::JoinHandle;

/// The nice value of a background thread (0 is the default, 19 the lowest).
const NICE: i32 = 10;

/// Runs `work` on a new thread named `name` at the background priority.
pub fn spawn<T: Send + 'static>(
    name: &str,
    work: impl FnOnce() -> T + Send + 'static,
) -> io::Result<JoinHandle<T>> {
    std::thread::Builder::new()
        .name(name.into())
        .spawn(move || {
            lower_priority();
            work()
        })
}

/// Lowers the calling thread's priority to [`NICE`] (on Linux the nice value is a thread's
/// own, not the process's). Elsewhere, or when refused, the thread keeps its priority.
fn lower_priority() {
    #[cfg(target_os = "linux")]
    // SAFETY: setpriority only reads its arguments; `0` names the calling thread.
    unsafe {
        libc::setpriority(libc::PRIO_PROCESS, 0, NICE);
    }
}
