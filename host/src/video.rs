//! A video of a MuJoCo walk: the model (`model.xml`) and the state trajectory (`qpos.csv`) the
//! simulator wrote are rendered headless (EGL, Mesa's software rasteriser) by
//! `scripts/render_walk.py` with MuJoCo's own renderer from PyPI's `mujoco==3.17.0` (the same
//! version the simulator links) and encoded by ffmpeg. `scripts/render-setup.sh` installs what
//! it needs into `.venv-render/`.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The repository root: the working directory when it holds the renderer, else the one this
/// crate was built from.
fn root() -> PathBuf {
    let here = PathBuf::from(".");
    if here.join("scripts/render_walk.py").is_file() {
        here
    } else {
        PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
    }
}

/// The renderer's Python: `WALKER_RENDER_PYTHON`, else `.venv-render/bin/python` of the
/// repository.
fn python(root: &Path) -> PathBuf {
    std::env::var_os("WALKER_RENDER_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join(".venv-render/bin/python"))
}

/// Renders `model` + `qpos` to `out` (`.mp4`, or `.gif` by its extension).
pub fn render(model: &Path, qpos: &Path, out: &Path) -> Result<(), String> {
    let root = root();
    let py = python(&root);
    let script = root.join("scripts/render_walk.py");
    if !py.exists() || !script.exists() {
        return Err(format!(
            "the renderer is not installed ({} or {} missing): run `bash scripts/render-setup.sh` from the repository root",
            py.display(),
            script.display()
        ));
    }
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    let mut cmd = Command::new(&py);
    cmd.arg(&script)
        .arg("--model")
        .arg(model)
        .arg("--qpos")
        .arg(qpos)
        .arg("--out")
        .arg(out);
    if out.extension().is_some_and(|e| e == "gif") {
        cmd.args(["--gif", "--width", "320", "--height", "240", "--fps", "15"]);
    }
    let status = cmd
        .status()
        .map_err(|e| format!("cannot start {}: {e}", py.display()))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("the renderer failed ({status})"))
    }
}
