//! Forwarding the store to the lab's central database (`[station]`, `[sync]`; the work itself
//! is `src/sync/`): started with the service as a task that stops with it.
//!
//! [`Forwarding`] owns the forwarder's status, which only the forwarder's task changes and
//! `status` shows. The forwarder only reads what the store committed, so acquisition never
//! waits on it; an unreachable server is retried with back-off and shown in `status`.

use std::sync::{Arc, Mutex};

use crate::sync::{BatchReport, Forwarder, ForwarderOptions, SyncStatus};

use super::ServiceError;
use super::context::Context;

/// The running forwarder, as the service sees it: its status.
pub(super) struct Forwarding {
    status: Arc<Mutex<SyncStatus>>,
}

impl Forwarding {
    /// Starts forwarding the store with `options`, until the service stops.
    pub(super) async fn start(
        ctx: &Context,
        options: ForwarderOptions,
    ) -> Result<Forwarding, ServiceError> {
        tracing::info!(
            station = %options.station,
            central = %crate::sync::redact(&options.url),
            "forwarding the store to the central database"
        );
        let forwarder = Forwarder::for_store(&ctx.store, options)
            .await
            .map_err(|e| crate::store::StoreError::from(sqlx::Error::Protocol(e.to_string())))?;
        let status = forwarder.status();
        let (guard, mut stop) = ctx.task_slot().await?;
        tokio::spawn(async move {
            let _guard = guard;
            let mut on_batch = |r: &BatchReport| {
                tracing::debug!("forwarded: {r}");
            };
            forwarder
                .run(async move { stop.recv().await }, &mut on_batch)
                .await;
        });
        Ok(Forwarding { status })
    }

    /// Backlog, last error and the like, as of now.
    pub(super) fn status(&self) -> SyncStatus {
        self.status
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }
}
