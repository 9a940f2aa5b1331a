//! Model workers behind a bounded queue. The models are CPU-bound and hold caches, so each
//! worker is a thread that owns its own copy and runs one task at a time; requests wait in a
//! queue of fixed depth, and a request that finds it full is answered 429 at once instead of
//! piling up. A task that waited past its deadline is dropped unrun.

use super::error::ApiError;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::oneshot;

type Task<M> = Box<dyn FnOnce(&mut M) + Send>;

/// A pool of workers, each owning an `M`.
pub struct Engine<M> {
    name: &'static str,
    queue: SyncSender<Task<M>>,
    capacity: usize,
    waiting: Arc<AtomicUsize>,
    active: Arc<AtomicUsize>,
}

impl<M> Clone for Engine<M> {
    fn clone(&self) -> Engine<M> {
        Engine {
            name: self.name,
            queue: self.queue.clone(),
            capacity: self.capacity,
            waiting: self.waiting.clone(),
            active: self.active.clone(),
        }
    }
}

impl<M: 'static> Engine<M> {
    /// Starts one worker per model; up to `capacity` tasks wait for them.
    pub fn start(name: &'static str, models: Vec<M>, capacity: usize) -> Engine<M>
    where
        M: Send,
    {
        let (queue, tasks) = sync_channel::<Task<M>>(capacity);
        let tasks = Arc::new(Mutex::new(tasks));
        let waiting = Arc::new(AtomicUsize::new(0));
        let active = Arc::new(AtomicUsize::new(0));
        for (k, mut model) in models.into_iter().enumerate() {
            let (tasks, active) = (tasks.clone(), active.clone());
            std::thread::Builder::new()
                .name(format!("anymo-{name}-{k}"))
                .spawn(move || {
                    while let Some(task) = next(&tasks) {
                        active.fetch_add(1, Ordering::SeqCst);
                        task(&mut model);
                        active.fetch_sub(1, Ordering::SeqCst);
                    }
                })
                .expect("starting a worker thread");
        }
        Engine { name, queue, capacity, waiting, active }
    }

    /// Tasks waiting for a worker now.
    pub fn waiting(&self) -> usize {
        self.waiting.load(Ordering::Relaxed)
    }

    /// Tasks a worker is running now.
    pub fn active(&self) -> usize {
        self.active.load(Ordering::SeqCst)
    }

    /// Runs `work` on a worker and waits for its answer, at most `timeout` in all.
    pub async fn run<T: Send + 'static>(
        &self,
        timeout: Duration,
        work: impl FnOnce(&mut M) -> Result<T, ApiError> + Send + 'static,
    ) -> Result<T, ApiError> {
        let deadline = Instant::now() + timeout;
        let (answer, answered) = oneshot::channel();
        let waiting = self.waiting.clone();
        let task: Task<M> = Box::new(move |model: &mut M| {
            waiting.fetch_sub(1, Ordering::Relaxed);
            if Instant::now() >= deadline || answer.is_closed() {
                return;
            }
            // A request that panics a model answers an error and leaves the worker running.
            let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| work(model)))
                .unwrap_or_else(|_| Err(ApiError::internal("the model failed on this request (it panicked)")));
            let _ = answer.send(result);
        });
        self.waiting.fetch_add(1, Ordering::Relaxed);
        if let Err(e) = self.queue.try_send(task) {
            self.waiting.fetch_sub(1, Ordering::Relaxed);
            return Err(match e {
                TrySendError::Full(_) => ApiError::busy(self.name, self.capacity),
                TrySendError::Disconnected(_) => {
                    ApiError::unavailable(format!("the {} workers have stopped", self.name))
                }
            });
        }
        match tokio::time::timeout(timeout, answered).await {
            Ok(Ok(result)) => result,
            Ok(Err(_)) => Err(ApiError::timeout(timeout.as_secs_f64())),
            Err(_) => Err(ApiError::timeout(timeout.as_secs_f64())),
        }
    }

    /// Queues `work` without waiting for it; false when the queue is full.
    pub fn spawn(&self, work: impl FnOnce(&mut M) + Send + 'static) -> bool {
        let waiting = self.waiting.clone();
        waiting.fetch_add(1, Ordering::Relaxed);
        let task: Task<M> = Box::new(move |model: &mut M| {
            waiting.fetch_sub(1, Ordering::Relaxed);
            work(model)
        });
        let queued = self.queue.try_send(task).is_ok();
        if !queued {
            self.waiting.fetch_sub(1, Ordering::Relaxed);
        }
        queued
    }
}

/// The next task, or `None` once every sender is gone (the server stopped).
fn next<M>(tasks: &Mutex<Receiver<Task<M>>>) -> Option<Task<M>> {
    tasks.lock().ok()?.recv().ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicBool;
    use std::sync::mpsc::channel;

    /// Yields until `condition` holds: the workers are threads, so the test waits on what they
    /// report rather than on a guess at how long they take.
    async fn until(condition: impl Fn() -> bool) {
        while !condition() {
            tokio::task::yield_now().await;
        }
    }

    /// A worker whose model blocks each task until the test releases it.
    fn gated() -> (Engine<Receiver<()>>, std::sync::mpsc::Sender<()>) {
        let (release, gate) = channel();
        (Engine::start("test", vec![gate], 1), release)
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_full_queue_refuses_at_once_and_the_queued_task_still_runs() {
        let (engine, release) = gated();
        let long = Duration::from_secs(30);
        let running = tokio::spawn({
            let engine = engine.clone();
            async move { engine.run(long, |gate| Ok(gate.recv().is_ok())).await }
        });
        // The worker takes the first task off the queue and blocks on it.
        until(|| engine.active() == 1).await;
        let queued = tokio::spawn({
            let engine = engine.clone();
            async move { engine.run(long, |gate| Ok(gate.recv().is_ok())).await }
        });
        until(|| engine.waiting() == 1).await;
        let refused = engine.run(long, |_| Ok(true)).await.unwrap_err();
        assert_eq!((refused.code, refused.retry_after), ("busy", Some(1)));
        assert!(refused.message.contains("(1 waiting)"), "{}", refused.message);
        release.send(()).unwrap();
        release.send(()).unwrap();
        assert!(running.await.unwrap().unwrap());
        assert!(queued.await.unwrap().unwrap());
        assert_eq!(engine.waiting(), 0);
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_task_past_its_deadline_times_out_and_never_runs() {
        let (engine, release) = gated();
        let blocker = tokio::spawn({
            let engine = engine.clone();
            async move { engine.run(Duration::from_secs(30), |gate| Ok(gate.recv().is_ok())).await }
        });
        until(|| engine.active() == 1).await;
        let ran = Arc::new(AtomicBool::new(false));
        let flag = ran.clone();
        let late = engine
            .run(Duration::from_millis(50), move |_| {
                flag.store(true, Ordering::SeqCst);
                Ok(())
            })
            .await;
        assert_eq!(late.unwrap_err().code, "timeout");
        release.send(()).unwrap();
        assert!(blocker.await.unwrap().unwrap());
        // The blocker answers before its worker takes the expired task off the one-place queue;
        // once it has, the next task queues behind it and is answered after it.
        until(|| engine.waiting() == 0).await;
        engine.run(Duration::from_secs(30), |_| Ok(())).await.unwrap();
        assert!(!ran.load(Ordering::SeqCst), "a task whose client gave up is dropped unrun");
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_panicking_task_answers_an_error_and_the_worker_goes_on() {
        let engine = Engine::start("test", vec![0u32], 4);
        let failed =
            engine.run(Duration::from_secs(30), |_: &mut u32| -> Result<(), ApiError> { panic!("boom") }).await;
        assert_eq!(failed.unwrap_err().code, "internal");
        let counted = engine
            .run(Duration::from_secs(30), |n: &mut u32| {
                *n += 1;
                Ok(*n)
            })
            .await;
        assert_eq!(counted.unwrap(), 1);
    }
}
