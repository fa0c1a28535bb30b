//! The bound on import bodies held in memory at once, across every door of the daemon
//! (`POST /scans/import` and the watch folder): one [`ImportBudget`] per service, sized by
//! `[ingest] max_held_mib`.
//!
//! Each door bounds one file (`[ingest] max_file_mib`, the API's import body limit); this
//! bounds their sum, so that a dozen uploads at once, or a burst of files in the watch folder,
//! cannot hold more than the bound between them. A door asks for a file's bytes before it
//! reads a byte of it and holds them ([`HeldBytes`]) until the import is over, the file's
//! parse included. The API refuses at once when the bytes are not free (HTTP 503 naming the
//! limit; the client retries); the watch folder waits, since its files wait in the folder
//! anyway.
//!
//! The budget counts what is read, not what a reader builds from it: each reader's own
//! working memory is bounded where the reader is (`src/formats/`).

use std::sync::Arc;

use tokio::sync::{OwnedSemaphorePermit, Semaphore};

/// Bytes are counted in KiB, so that a budget of terabytes still fits the semaphore's u32
/// requests.
const UNIT: u64 = 1024;

/// Why bytes could not be held.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BudgetError {
    /// Other imports hold the bytes now.
    #[error(
        "the daemon already holds {held_mib} MiB of import bodies and this one needs \
         {asked_mib} MiB more, over the bound of {total_mib} MiB on import bodies held at once \
         ([ingest] max_held_mib); retry when the imports in progress are done, or raise the \
         bound"
    )]
    Full {
        asked_mib: u64,
        held_mib: u64,
        total_mib: u64,
    },
    /// One file larger than the whole budget: it can never be held.
    #[error(
        "this import needs {asked_mib} MiB, more than the bound of {total_mib} MiB on import \
         bodies held at once ([ingest] max_held_mib); raise the bound or send a smaller file"
    )]
    TooLarge { asked_mib: u64, total_mib: u64 },
}

/// The service's budget of import bytes (module docs); clones share it.
#[derive(Debug, Clone)]
pub struct ImportBudget {
    permits: Arc<Semaphore>,
    /// The bound, in [`UNIT`]s.
    total: u64,
}

/// Bytes held for one import; given back when dropped.
#[derive(Debug)]
pub struct HeldBytes {
    _permit: OwnedSemaphorePermit,
}

fn mib(units: u64) -> u64 {
    (units * UNIT).div_ceil(1 << 20)
}

impl ImportBudget {
    /// A budget of `bytes` (rounded up to a KiB).
    pub fn new(bytes: u64) -> ImportBudget {
        let total = bytes.div_ceil(UNIT).max(1);
        ImportBudget {
            permits: Arc::new(Semaphore::new(total as usize)),
            total,
        }
    }

    /// The bound, in bytes.
    pub fn total_bytes(&self) -> u64 {
        self.total * UNIT
    }

    /// The bytes held by imports now.
    pub fn held_bytes(&self) -> u64 {
        (self.total - self.permits.available_permits() as u64) * UNIT
    }

    /// `bytes` in units, or `TooLarge` when the whole budget could not hold them.
    fn units(&self, bytes: u64) -> Result<u32, BudgetError> {
        let units = bytes.div_ceil(UNIT).max(1);
        if units > self.total {
            return Err(BudgetError::TooLarge {
                asked_mib: mib(units),
                total_mib: mib(self.total),
            });
        }
        Ok(units as u32)
    }

    /// Holds `bytes` now, or says why not (never waits).
    pub fn try_hold(&self, bytes: u64) -> Result<HeldBytes, BudgetError> {
        let units = self.units(bytes)?;
        match self.permits.clone().try_acquire_many_owned(units) {
            Ok(permit) => Ok(HeldBytes { _permit: permit }),
            Err(_) => Err(BudgetError::Full {
                asked_mib: mib(units as u64),
                held_mib: mib(self.total - self.permits.available_permits() as u64),
                total_mib: mib(self.total),
            }),
        }
    }

    /// Holds `bytes`, waiting until other imports have given back enough.
    pub async fn hold(&self, bytes: u64) -> Result<HeldBytes, BudgetError> {
        let units = self.units(bytes)?;
        let permit = self
            .permits
            .clone()
            .acquire_many_owned(units)
            .await
            .expect("the budget's semaphore is never closed");
        Ok(HeldBytes { _permit: permit })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_held_are_bounded_as_a_whole_and_given_back() {
        let b = ImportBudget::new(10 << 20);
        let first = b.try_hold(6 << 20).unwrap();
        assert_eq!(b.held_bytes(), 6 << 20);
        let e = b.try_hold(5 << 20).unwrap_err();
        assert_eq!(
            e,
            BudgetError::Full {
                asked_mib: 5,
                held_mib: 6,
                total_mib: 10
            }
        );
        assert!(e.to_string().contains("[ingest] max_held_mib"), "{e}");
        // What fits beside it is held.
        let second = b.try_hold(4 << 20).unwrap();
        assert_eq!(b.held_bytes(), 10 << 20);
        drop(first);
        drop(second);
        assert_eq!(b.held_bytes(), 0);
        let e = b.try_hold(11 << 20).unwrap_err();
        assert!(
            matches!(e, BudgetError::TooLarge { asked_mib: 11, .. }),
            "{e}"
        );
        // A byte counts as a whole KiB.
        let tiny = b.try_hold(1).unwrap();
        assert_eq!(b.held_bytes(), 1024);
        drop(tiny);
    }

    #[tokio::test]
    async fn hold_waits_for_bytes_to_be_given_back() {
        let b = ImportBudget::new(8 << 20);
        let first = b.try_hold(8 << 20).unwrap();
        let b2 = b.clone();
        let waiter = tokio::spawn(async move { b2.hold(3 << 20).await.map(|_| ()) });
        tokio::task::yield_now().await;
        assert!(!waiter.is_finished());
        drop(first);
        waiter.await.unwrap().unwrap();
        assert!(b.hold(9 << 20).await.is_err());
    }
}
