//! The `polyspline` command line: process set-up (signals, the Vulkan runtime directory) and
//! the one-line error report; the subcommands are in [`cli`].

mod cli;

use std::process::ExitCode;

fn main() -> ExitCode {
    // Mesa's Vulkan drivers print an error line while adapters are probed when the process has
    // no runtime directory; give it the temporary directory instead.
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        // SAFETY: no other thread exists yet (rayon and wgpu start theirs later).
        unsafe { std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir()) };
    }
    // Printing into a closed pipe (`polyspline info M | head`) ends the process quietly, as
    // other command-line tools do, instead of panicking in `println!`.
    #[cfg(unix)]
    // SAFETY: restores the default disposition of SIGPIPE before any other thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    #[cfg(unix)]
    remove_temporaries_on_signals();
    let cli = cli::parse();
    match cli::run(cli) {
        Ok(status) => ExitCode::from(status),
        Err(e) => {
            // One bounded line, whatever the message quotes from the input.
            let line = polyspline::mesh::raw::one_line(&e.to_string(), MAX_ERROR_CHARS);
            eprintln!("polyspline: error: {line}");
            ExitCode::FAILURE
        }
    }
}

/// Longest error line (characters after the prefix); paths and a quoted excerpt fit.
const MAX_ERROR_CHARS: usize = 2000;

/// SIGINT, SIGTERM and SIGHUP remove the temporary output files being written, then end the
/// process with status 128 + the signal (130, 143, 129). The signals are blocked in every
/// thread and taken by one thread with `sigwait`, so the clean-up runs as ordinary code (it
/// takes a lock and unlinks files, which an asynchronous handler could not do safely).
#[cfg(unix)]
fn remove_temporaries_on_signals() {
    // SAFETY: plain libc calls on a local signal set; called before any other thread exists,
    // so every thread started later inherits the mask.
    let set = unsafe {
        let mut set: libc::sigset_t = std::mem::zeroed();
        libc::sigemptyset(&mut set);
        for sig in [libc::SIGINT, libc::SIGTERM, libc::SIGHUP] {
            libc::sigaddset(&mut set, sig);
        }
        libc::pthread_sigmask(libc::SIG_BLOCK, &set, std::ptr::null_mut());
        set
    };
    std::thread::spawn(move || {
        loop {
            let mut sig = 0;
            // SAFETY: `set` and `sig` are valid for the call.
            if unsafe { libc::sigwait(&set, &mut sig) } != 0 {
                continue;
            }
            let removed = polyspline::io::output::remove_registered_temporaries();
            // A rank of a failed MPI job, ending after the job's one error line: the launcher
            // stops the ranks that are still finishing; that is not news.
            #[cfg(feature = "mpi")]
            if cli::launch::failed() {
                std::process::exit(1);
            }
            let name = match sig {
                libc::SIGINT => "SIGINT",
                libc::SIGTERM => "SIGTERM",
                _ => "SIGHUP",
            };
            eprintln!(
                "polyspline: interrupted by {name}{}",
                if removed > 0 {
                    "; the unfinished output was removed"
                } else {
                    ""
                }
            );
            std::process::exit(128 + sig);
        }
    });
}
