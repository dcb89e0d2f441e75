//! A video of a MuJoCo walk: the model (`model.xml`) and the state trajectory (`qpos.csv`) the
//! simulator wrote are rendered headless (EGL, Mesa's software rasteriser) by
//! `scripts/render_walk.py` with MuJoCo's own renderer from PyPI's `mujoco==3.17.0` (the same
//! version the simulator links) and encoded by ffmpeg. `scripts/render-setup.sh` installs what
//! it needs into `.venv-render/`. The renderer's `--progress` lines (`progress K N`) drive the
//! frames' progress ([`crate::progress::Progress`]).

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use crate::progress::Progress;

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

/// A `progress K N` line of the renderer's `--progress` output: (frames done, frames).
pub fn progress_line(line: &str) -> Option<(usize, usize)> {
    let mut w = line.strip_prefix("progress ")?.split_whitespace();
    let k = w.next()?.parse().ok()?;
    let n = w.next()?.parse().ok()?;
    match w.next() {
        None => Some((k, n)),
        Some(_) => None,
    }
}

/// Renders `model` + `qpos` to `out` (`.mp4`, or `.gif` by its extension), with the frames'
/// progress on stderr ([`crate::progress::Progress`]: a bar on a terminal, a line at each
/// tenth otherwise); the renderer's other output goes to stdout.
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
        .arg(out)
        .arg("--progress")
        .stdout(Stdio::piped());
    if out.extension().is_some_and(|e| e == "gif") {
        cmd.args(["--gif", "--width", "320", "--height", "240", "--fps", "15"]);
    }
    let mut child = cmd
        .spawn()
        .map_err(|e| format!("cannot start {}: {e}", py.display()))?;
    let mut progress: Option<Progress> = None;
    if let Some(stdout) = child.stdout.take() {
        for line in BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            match progress_line(&line) {
                Some((k, n)) => {
                    let p = progress.get_or_insert_with(|| {
                        let p = Progress::stderr(n, "rendering");
                        p.start(&out.display().to_string());
                        p
                    });
                    p.position(k, "frames rendered");
                }
                None => println!("{line}"),
            }
        }
    }
    if let Some(p) = progress {
        p.finish();
    }
    let status = child.wait().map_err(|e| format!("the renderer: {e}"))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("the renderer failed ({status})"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_renderers_progress_lines_are_read_and_nothing_else() {
        assert_eq!(progress_line("progress 3 365"), Some((3, 365)));
        assert_eq!(progress_line("progress 365 365"), Some((365, 365)));
        for other in [
            "render_walk: wrote out/walk.mp4: 365 frames",
            "progress",
            "progress 3",
            "progress x 3",
            "progress 3 4 5",
        ] {
            assert_eq!(progress_line(other), None, "{other}");
        }
    }
}
