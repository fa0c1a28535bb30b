//! Rebuild when `migrations/` changes: `sqlx::migrate!()` embeds the folder at compile time, and
//! Cargo notices an edited migration but not a new file without this line.
fn main() {
    println!("cargo:rerun-if-changed=migrations");
}
