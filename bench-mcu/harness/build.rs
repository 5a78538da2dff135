//! The harness's link script: found in this directory, used only by this crate.
fn main() {
    let dir = std::env::var("CARGO_MANIFEST_DIR").unwrap_or_default();
    println!("cargo:rustc-link-search={dir}");
    println!("cargo:rustc-link-arg=-Tbench.x");
    println!("cargo:rerun-if-changed=bench.x");
}
