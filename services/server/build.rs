//! Two build steps:
//! - compiles `proto/anymo.proto` into the gRPC server and client, with protox (pure Rust: no
//!   protoc to install), and keeps the descriptor set for server reflection;
//! - gathers the web page: its own files from `web/`, and three.js with its BVH loader and orbit
//!   controls from the npm package pinned in `web/vendor/package-lock.json` (installed here with
//!   `npm ci` into OUT_DIR, never fetched by the browser from a CDN). Every file is embedded in
//!   the binary with a gzip copy and an ETag, so the server needs nothing beside it.

use prost::Message;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

type BuildResult<T> = Result<T, Box<dyn std::error::Error>>;

/// The page's own files, served under `/ui/`.
const OWN: &[&str] = &[
    "index.html",
    "style.css",
    "app.js",
    "api.js",
    "viewer.js",
    "dom.js",
    "skeletons.js",
    "generate.js",
    "library.js",
    "transfer.js",
    "quality.js",
];

/// What is taken from the npm package `three`: (path in the package, name under `/ui/vendor/`).
const THREE: &[(&str, &str)] = &[
    ("build/three.core.js", "three.core.js"),
    ("build/three.module.js", "three.module.js"),
    ("examples/jsm/loaders/BVHLoader.js", "BVHLoader.js"),
    ("examples/jsm/controls/OrbitControls.js", "OrbitControls.js"),
    ("LICENSE", "three.LICENSE.txt"),
];

fn main() -> BuildResult<()> {
    let out = PathBuf::from(std::env::var_os("OUT_DIR").ok_or("cargo sets OUT_DIR")?);
    proto(&out)?;
    web(&out)
}

fn proto(out: &Path) -> BuildResult<()> {
    println!("cargo:rerun-if-changed=proto/anymo.proto");
    let descriptors = protox::compile(["anymo.proto"], ["proto"])?;
    std::fs::write(out.join("anymo_descriptor.bin"), descriptors.encode_to_vec())?;
    tonic_prost_build::configure().compile_fds(descriptors)?;
    Ok(())
}

/// Installs the pinned npm packages into `OUT_DIR/web-vendor` unless that lock is already there.
fn npm_install(out: &Path) -> BuildResult<PathBuf> {
    let dir = out.join("web-vendor");
    let lock = std::fs::read("web/vendor/package-lock.json")?;
    let installed = dir.join("node_modules/three/package.json").exists()
        && std::fs::read(dir.join("package-lock.json")).is_ok_and(|l| l == lock);
    if !installed {
        std::fs::create_dir_all(&dir)?;
        std::fs::copy("web/vendor/package.json", dir.join("package.json"))?;
        std::fs::write(dir.join("package-lock.json"), &lock)?;
        let status = Command::new("npm")
            .args(["ci", "--ignore-scripts", "--no-audit", "--no-fund", "--loglevel=error"])
            .current_dir(&dir)
            .status()
            .map_err(|e| {
                format!(
                    "the web page vendors three.js from npm at build time, and npm could not start ({e}); \
                     install Node.js with npm (Debian: apt-get install npm)"
                )
            })?;
        if !status.success() {
            return Err(format!(
                "`npm ci` in {} failed ({status}): the web page needs the npm package three from the npm registry",
                dir.display()
            )
            .into());
        }
    }
    Ok(dir.join("node_modules/three"))
}

/// The vendored modules import `three` by its bare name; with no import map (which the page's
/// content security policy would have to allow inline) they import the served file instead.
fn resolve_three(name: &str, text: Vec<u8>) -> BuildResult<Vec<u8>> {
    if !name.ends_with(".js") || name.starts_with("three.") {
        return Ok(text);
    }
    let text = String::from_utf8(text)?;
    let bare = "from 'three';";
    if text.matches(bare).count() != 1 {
        return Err(format!("{name}: expected one `{bare}` to point at the served three.module.js").into());
    }
    Ok(text.replace(bare, "from './three.module.js';").into_bytes())
}

fn mime(name: &str) -> &'static str {
    match name.rsplit('.').next() {
        Some("html") => "text/html; charset=utf-8",
        Some("css") => "text/css; charset=utf-8",
        Some("js") => "text/javascript; charset=utf-8",
        _ => "text/plain; charset=utf-8",
    }
}

fn web(out: &Path) -> BuildResult<()> {
    println!("cargo:rerun-if-changed=web/vendor/package.json");
    println!("cargo:rerun-if-changed=web/vendor/package-lock.json");
    let three = npm_install(out)?;
    let mut files: Vec<(String, Vec<u8>)> = Vec::new();
    for name in OWN {
        let path = Path::new("web").join(name);
        println!("cargo:rerun-if-changed={}", path.display());
        files.push((name.to_string(), std::fs::read(&path).map_err(|e| format!("{}: {e}", path.display()))?));
    }
    for (from, name) in THREE {
        let text = std::fs::read(three.join(from)).map_err(|e| format!("three/{from}: {e}"))?;
        files.push((format!("vendor/{name}"), resolve_three(name, text)?));
    }
    let assets = out.join("web");
    std::fs::create_dir_all(assets.join("vendor"))?;
    let mut table = String::from("&[\n");
    for (name, body) in &files {
        let raw = assets.join(name);
        std::fs::write(&raw, body)?;
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
        gz.write_all(body)?;
        let gzipped = raw.with_extension(format!("{}.gz", raw.extension().and_then(|e| e.to_str()).unwrap_or("")));
        std::fs::write(&gzipped, gz.finish()?)?;
        let etag = &blake3::hash(body).to_hex()[..16];
        writeln!(
            table,
            "    Asset {{ path: {name:?}, mime: {mime:?}, etag: \"\\\"{etag}\\\"\", body: include_bytes!({raw:?}), \
             gzip: include_bytes!({gzipped:?}) }},",
            mime = mime(name),
        )?;
    }
    table.push(']');
    std::fs::write(out.join("web_assets.rs"), table)?;
    Ok(())
}
