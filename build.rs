//! Rebuild when `migrations/` or `migrations-central/` changes: `sqlx::migrate!()` embeds the
//! folders at compile time, and Cargo notices an edited migration but not a new file without
//! these lines.
//!
//! Also sets `BRDFD_BUILD_UNIX` (seconds since the epoch: `SOURCE_DATE_EPOCH` when set, else
//! the time this script ran), the lower bound `brdfd doctor` holds the clock to.
fn main() {
    println!("cargo:rerun-if-changed=migrations");
    println!("cargo:rerun-if-changed=migrations-central");
    println!("cargo:rerun-if-env-changed=SOURCE_DATE_EPOCH");
    let built = std::env::var("SOURCE_DATE_EPOCH")
        .ok()
        .and_then(|s| s.trim().parse::<u64>().ok())
        .unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_secs())
                .unwrap_or(0)
        });
    println!("cargo:rustc-env=BRDFD_BUILD_UNIX={built}");
}
