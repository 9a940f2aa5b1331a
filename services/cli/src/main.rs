//! The `anymo` command line: motion files, the corpus, the models, search and the server.

mod commands;

use anyhow::Result;
use clap::Parser;

fn main() -> Result<()> {
    pin_candle_threads();
    commands::Cli::parse().run()
}

/// Sets `RAYON_NUM_THREADS` to the cores available when the user has not set it. candle reads
/// the variable before every matrix product and, when it is unset, works the thread count out
/// from files under /sys each time, which on the models' small products costs more than the
/// product: with the variable set, embedding one query text goes from 48.5 to 80.9 texts/s and
/// a 4 s generation from 195 to 141 ms on 2 cores (`cargo bench -p anymo-server --bench serve`,
/// run with and without `RAYON_NUM_THREADS=2`; docs/measurements/server.md).
#[allow(unsafe_code)]
fn pin_candle_threads() {
    if std::env::var_os("RAYON_NUM_THREADS").is_none() {
        let cores = std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get);
        // SAFETY: the first thing `main` does, before any thread exists, so no other thread
        // can read or write the environment at the same time.
        unsafe { std::env::set_var("RAYON_NUM_THREADS", cores.to_string()) };
    }
}
