//! The `anymo` command line: motion files, the corpus, the models, search and the server.

mod commands;

use anyhow::Result;
use clap::Parser;

fn main() -> Result<()> {
    let cli = commands::Cli::parse();
    let cores = std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get);
    pin_candle_threads(cli.threads_per_call(cores));
    cli.run()
}

/// Sets `RAYON_NUM_THREADS` to `threads` when the user has not set it. candle reads
/// the variable before every matrix product and, when it is unset, works the thread count out
/// from files under /sys each time, which on the models' small products costs more than the
/// product: with the variable set, embedding one query text goes from 48.5 to 80.9 texts/s and
/// a 4 s generation from 195 to 141 ms on 2 cores (`cargo bench -p anymo-server --bench serve`,
/// run with and without `RAYON_NUM_THREADS=2`; docs/measurements/server.md).
#[allow(unsafe_code)]
fn pin_candle_threads(threads: usize) {
    if std::env::var_os("RAYON_NUM_THREADS").is_none() {
        // SAFETY: `main` does this before any thread exists (parsing the arguments starts
        // none), so no other thread can read or write the environment at the same time.
        unsafe { std::env::set_var("RAYON_NUM_THREADS", threads.to_string()) };
    }
}
