//! Graceful shutdown, the mini-redis way.
//!
//! - A broadcast channel says "stop": every long-lived task holds a [`Shutdown`] listener and
//!   checks it in its `select!`.
//! - Every such task also holds a clone of an mpsc sender ([`TaskGuard`]). The daemon keeps
//!   the receiver; once it has said "stop" and dropped its own sender, `recv()` returning
//!   `None` means every task has finished — no task list to keep, no join handles to collect.
//!
//! What "finished" means per task is the task's business: the scan in progress aborts the
//! instruments (the reading being fetched completes or is dropped), stores what it has and
//! marks the scan `aborted` with the reason; a running fit stops at its next generation and is
//! left `running`, to be queued again at the next start (a fit is deterministic by its seed).

use std::time::Duration;

use tokio::sync::{broadcast, mpsc};

/// Listens for the stop signal. Cheap to create from a [`Coordinator`].
#[derive(Debug)]
pub struct Shutdown {
    stopping: bool,
    notify: broadcast::Receiver<()>,
}

impl Shutdown {
    /// Whether the stop signal has been received.
    pub fn is_shutdown(&self) -> bool {
        self.stopping
    }

    /// Waits for the stop signal (returns at once if it was already received).
    pub async fn recv(&mut self) {
        if self.stopping {
            return;
        }
        // Err: the coordinator is gone (it said stop and dropped the sender) or this listener
        // lagged; both mean stop.
        let _ = self.notify.recv().await;
        self.stopping = true;
    }
}

/// Held by every task the daemon must wait for; dropping it says "this task is done".
#[derive(Debug, Clone)]
pub struct TaskGuard {
    _done: mpsc::Sender<()>,
}

/// The daemon's side: hands out listeners and guards, says stop, waits for the tasks.
#[derive(Debug)]
pub struct Coordinator {
    notify: broadcast::Sender<()>,
    done_tx: Option<mpsc::Sender<()>>,
    done_rx: mpsc::Receiver<()>,
}

impl Default for Coordinator {
    fn default() -> Self {
        Coordinator::new()
    }
}

impl Coordinator {
    pub fn new() -> Coordinator {
        let (notify, _) = broadcast::channel(1);
        let (done_tx, done_rx) = mpsc::channel(1);
        Coordinator {
            notify,
            done_tx: Some(done_tx),
            done_rx,
        }
    }

    /// A listener for a new task. A listener made after [`Coordinator::stop`] reports stop at
    /// once.
    pub fn listener(&self) -> Shutdown {
        Shutdown {
            stopping: self.done_tx.is_none(),
            notify: self.notify.subscribe(),
        }
    }

    /// A guard for a new task; `None` once stopping (start no new task then).
    pub fn guard(&self) -> Option<TaskGuard> {
        self.done_tx
            .as_ref()
            .map(|tx| TaskGuard { _done: tx.clone() })
    }

    /// Says stop to every listener and waits up to `grace` for every guard to be dropped.
    /// Returns whether they all were.
    pub async fn stop(&mut self, grace: Duration) -> bool {
        let _ = self.notify.send(());
        self.done_tx = None;
        tokio::time::timeout(grace, self.done_rx.recv())
            .await
            .is_ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn stop_waits_for_every_guarded_task() {
        let mut c = Coordinator::new();
        let (tx, mut rx) = mpsc::unbounded_channel();
        for i in 0..3u64 {
            let mut listener = c.listener();
            let guard = c.guard().unwrap();
            let tx = tx.clone();
            tokio::spawn(async move {
                listener.recv().await;
                // Some clean-up that takes a while.
                tokio::time::sleep(Duration::from_millis(10 * i)).await;
                tx.send(i).unwrap();
                drop(guard);
            });
        }
        drop(tx);
        assert!(c.stop(Duration::from_secs(5)).await);
        let mut finished = Vec::new();
        while let Some(i) = rx.recv().await {
            finished.push(i);
        }
        finished.sort();
        assert_eq!(
            finished,
            [0, 1, 2],
            "every task ran its clean-up before stop returned"
        );
        assert!(c.guard().is_none());
        assert!(c.listener().is_shutdown());
    }

    #[tokio::test]
    async fn stop_gives_up_after_the_grace_period() {
        let mut c = Coordinator::new();
        let _stuck = c.guard().unwrap();
        assert!(!c.stop(Duration::from_millis(20)).await);
    }
}
