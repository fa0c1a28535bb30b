//! Rebuild when `migrations/` or `migrations-central/` changes: `sqlx::migrate!()` embeds the
//! folders at compile time, and Cargo notices an edited migration but not a new file without
//! these lines.
fn main() {
    println!("cargo:rerun-if-changed=migrations");
    println!("cargo:rerun-if-changed=migrations-central");
}
