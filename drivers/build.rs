//! Says loudly when the driver is about to carry a static libusb.
//!
//! `libusb1-sys` looks for the system libusb with pkg-config and, when it finds none, compiles
//! its bundled copy and links that statically — without a word, and for good: its build script
//! does not look again when the `-dev` package is installed later, so a target directory that
//! once fell back keeps the static copy. Its `links = "usb-1.0"` metadata says which it did
//! (`DEP_USB_1.0_VENDORED`). The build goes on — `cargo run --release -- demo` must work on a
//! machine without the `-dev` package — but with a warning naming the fix; the Debian package
//! check (`.ci/deb-check`) refuses a static libusb (README "Licences").

fn main() {
    println!("cargo:rerun-if-env-changed=DEP_USB_1.0_VENDORED");
    let vendored = std::env::var_os("DEP_USB_1.0_VENDORED").is_some();
    let asked = std::env::var_os("CARGO_FEATURE_VENDORED_LIBUSB").is_some();
    if vendored && !asked {
        println!(
            "cargo:warning={}",
            "libusb1-sys did not find the system libusb (pkg-config libusb-1.0) and built its \
             bundled copy, which is linked statically. Install the system's development \
             package (Debian, Ubuntu: `apt-get install libusb-1.0-0-dev pkg-config`), then run \
             `cargo clean -p libusb1-sys` (its build script does not look again by itself); or \
             build with `--features vendored-libusb` to link the bundled copy on purpose \
             (LGPL-2.1: README \"Licences\")."
        );
    }
}
