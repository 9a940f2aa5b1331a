//! Shared reads of the store's clip signature (count and largest id), which tells a replica when
//! its index must catch up with the store. Every query needs one, so under load the reads
//! themselves would queue on the store: queries that arrive while a read is under way wait for
//! it and then share the next one. No query takes a read that began before it arrived, so a clip
//! another replica stored is seen by every query that comes after it.

use crate::error::ApiError;
use anymo_store::Store;
use std::future::Future;
use std::pin::Pin;
use std::sync::{Arc, Mutex, PoisonError};
use tokio::sync::OnceCell;

/// The store's clip signature: `(count, largest id)`.
pub type Signature = (i64, i64);

/// One read's answer, shared by the queries that joined it.
type Read = Arc<OnceCell<Result<Signature, ApiError>>>;

/// A read of the signature from wherever it comes from.
type Source = Box<dyn Fn() -> Pin<Box<dyn Future<Output = Result<Signature, ApiError>> + Send>> + Send + Sync>;

/// Reads of one store's signature, shared between the queries that arrive together.
pub struct SignatureReads {
    source: Source,
    /// The read not begun yet, which arriving queries join.
    next: Mutex<Option<Read>>,
    /// Held while a read is under way: one at a time.
    running: tokio::sync::Mutex<()>,
}

impl SignatureReads {
    /// Reads of `store`'s signature.
    pub fn new(store: Store) -> SignatureReads {
        SignatureReads::of(Box::new(move || {
            let store = store.clone();
            Box::pin(async move { store.clips_signature().await.map_err(ApiError::from) })
        }))
    }

    fn of(source: Source) -> SignatureReads {
        SignatureReads { source, next: Mutex::new(None), running: tokio::sync::Mutex::new(()) }
    }

    /// The store's signature, read after this call began.
    pub async fn read(&self) -> Result<Signature, ApiError> {
        let read = self.next.lock().unwrap_or_else(PoisonError::into_inner).get_or_insert_with(Read::default).clone();
        // Whichever joined query gets here first runs the read; if it is dropped midway (its client
        // went away), another one runs it.
        read.get_or_init(|| async {
            let _running = self.running.lock().await;
            // The read begins now: queries arriving from here on join the next one.
            {
                let mut next = self.next.lock().unwrap_or_else(PoisonError::into_inner);
                if next.as_ref().is_some_and(|n| Arc::ptr_eq(n, &read)) {
                    *next = None;
                }
            }
            (self.source)().await
        })
        .await
        .clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicI64, AtomicUsize, Ordering};
    use tokio::sync::Semaphore;

    /// A source whose reads see `clips` as it is when they begin, count themselves in `begun`,
    /// and finish only when `gate` lets them.
    fn gated(clips: Arc<AtomicI64>, begun: Arc<AtomicUsize>, gate: Arc<Semaphore>) -> SignatureReads {
        SignatureReads::of(Box::new(move || {
            let seen = clips.load(Ordering::SeqCst);
            begun.fetch_add(1, Ordering::SeqCst);
            let gate = gate.clone();
            Box::pin(async move {
                gate.acquire().await.expect("open").forget();
                Ok((seen, seen))
            })
        }))
    }

    async fn until(condition: impl Fn() -> bool) {
        while !condition() {
            tokio::task::yield_now().await;
        }
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn queries_arriving_during_a_read_share_the_next_one_and_see_the_store_as_of_their_arrival() {
        let (clips, begun, gate) =
            (Arc::new(AtomicI64::new(0)), Arc::new(AtomicUsize::new(0)), Arc::new(Semaphore::new(0)));
        let reads = Arc::new(gated(clips.clone(), begun.clone(), gate.clone()));
        let spawn = |reads: &Arc<SignatureReads>| {
            let reads = reads.clone();
            tokio::spawn(async move { reads.read().await.unwrap() })
        };
        let first = spawn(&reads);
        until(|| begun.load(Ordering::SeqCst) == 1).await;
        // A clip is stored while the first read is under way; the queries that arrive after it
        // must not take that read's answer.
        clips.store(1, Ordering::SeqCst);
        let later: Vec<_> = (0..8).map(|_| spawn(&reads)).collect();
        let joined = || reads.next.lock().unwrap().as_ref().map_or(0, Arc::strong_count);
        until(|| joined() == 1 + later.len()).await;
        gate.add_permits(2);
        assert_eq!(first.await.unwrap(), (0, 0));
        for query in later {
            assert_eq!(query.await.unwrap(), (1, 1));
        }
        assert_eq!(begun.load(Ordering::SeqCst), 2, "the eight later queries shared one read");
    }

    #[tokio::test]
    async fn a_store_failure_reaches_every_query_that_shared_the_read() {
        let reads =
            SignatureReads::of(Box::new(|| Box::pin(async { Err(ApiError::unavailable("the store is down")) })));
        let (a, b) = tokio::join!(reads.read(), reads.read());
        assert_eq!(a.unwrap_err().code, "unavailable");
        assert_eq!(b.unwrap_err().message, "the store is down");
    }
}
