//! Compiles every checkpoint of the repository's `checkpoints/` into the binary, so that an
//! installed or copied `anymo` needs no folder beside it: writes `OUT_DIR/built_in.rs`, a table
//! of `BuiltIn { name, card, weights }` with `include_str!`/`include_bytes!` of each pair.

use std::fmt::Write as _;
use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = Path::new(&std::env::var("CARGO_MANIFEST_DIR")?).join("../../checkpoints").canonicalize()?;
    println!("cargo:rerun-if-changed={}", dir.display());
    let mut names: Vec<String> = std::fs::read_dir(&dir)?
        .filter_map(|e| e.ok()?.file_name().to_str()?.strip_suffix(".safetensors").map(str::to_string))
        .filter(|name| dir.join(format!("{name}.json")).is_file())
        .collect();
    names.sort();
    let mut table = String::from("&[\n");
    for name in &names {
        let weights = dir.join(format!("{name}.safetensors"));
        let card = dir.join(format!("{name}.json"));
        println!("cargo:rerun-if-changed={}", weights.display());
        println!("cargo:rerun-if-changed={}", card.display());
        writeln!(
            table,
            "    anymo_models::checkpoint::BuiltIn {{ name: {name:?}, card: include_str!({card:?}), \
             weights: include_bytes!({weights:?}) }},"
        )?;
    }
    table.push(']');
    std::fs::write(Path::new(&std::env::var("OUT_DIR")?).join("built_in.rs"), table)?;
    Ok(())
}
