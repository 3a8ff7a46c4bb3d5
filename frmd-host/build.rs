//! Does nothing: it exists so that the `syn` build-dependency of Cargo.toml (a feature of
//! PyO3's macros, unified here so the Python wheel shares this crate's build) takes part in the
//! build. Without the line below Cargo would rerun it, and rebuild the crate, whenever any file
//! under frmd-host/ changes (frmd-host/python/ included).
fn main() {
    println!("cargo:rerun-if-changed=build.rs");
}
