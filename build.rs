//! Compiles `proto/tirewear.proto` with protox (pure Rust, no protoc needed):
//! the Rust types via prost-build, and the binary FileDescriptorSet that MCAP
//! schema records carry (embedded with `include_bytes!`).
use prost::Message;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    println!("cargo:rerun-if-changed=proto/tirewear.proto");
    let fds = protox::compile(["tirewear.proto"], ["proto"])?;
    let out = std::path::PathBuf::from(std::env::var("OUT_DIR")?);
    // Schema records carry the set without source info: smaller and what Foxglove expects.
    let mut bare = fds.clone();
    for f in &mut bare.file {
        f.source_code_info = None;
    }
    std::fs::write(out.join("tirewear_fds.bin"), bare.encode_to_vec())?;
    prost_build::Config::new().compile_fds(fds)?;
    Ok(())
}
