//! The firmware's defmt output decoded into a text log with the ELF's own table
//! (`defmt-decoder`, the library inside `defmt-print` / `probe-rs`).
//!
//! defmt sends a format string's index and its arguments in binary; the strings stay in the
//! ELF's `.defmt` section. In QEMU the frames arrive on the semihosting output (QEMU's stdout,
//! rzCOBS-encoded, `defmt-semihosting`): `walker fil` saves them to `OUT/firmware.defmt` and
//! decodes them after the run into `OUT/firmware.log`. On the robot defmt goes over RTT
//! (probe-rs decodes it itself); a raw stream saved by another tool, or by
//! `scripts/qemu-run.sh` (`ELF.defmt`), is decoded by `walker capture --defmt FILE --elf ELF`.
//!
//! Each frame becomes one line, `[timestamp] LEVEL message` as defmt-print prints it, followed
//! by ` (file:line)` when the ELF has the location. A malformed frame is counted and skipped
//! (rzCOBS resynchronises at the next frame); bytes after the last complete frame are counted
//! as a truncated tail (QEMU stopped mid-frame).

use std::fmt::Write as _;
use std::path::Path;

/// One decoded frame.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DefmtLine {
    /// Its level (`trace` … `error`), `None` for `println!`.
    pub level: Option<&'static str>,
    /// The line as defmt-print shows it (timestamp, level, message), without location.
    pub text: String,
    /// `file:line` of the log statement, when the ELF has debug information.
    pub location: Option<String>,
}

/// A decoded defmt stream.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DefmtLog {
    /// The frames, in order.
    pub lines: Vec<DefmtLine>,
    /// Frames that did not decode (skipped).
    pub malformed: usize,
    /// The stream ended inside a frame.
    pub truncated: bool,
}

impl DefmtLog {
    /// Lines at `warn` or `error` level.
    pub fn warnings(&self) -> impl Iterator<Item = &DefmtLine> {
        self.lines
            .iter()
            .filter(|l| matches!(l.level, Some("warn" | "error")))
    }

    /// The log as text, one line per frame, then a line on malformed frames / a cut tail.
    pub fn text(&self) -> String {
        let mut out = String::new();
        for l in &self.lines {
            out.push_str(&l.text);
            if let Some(loc) = &l.location {
                let _ = write!(out, " ({loc})");
            }
            out.push('\n');
        }
        if self.malformed > 0 {
            let _ = writeln!(
                out,
                "(walker: {} malformed defmt frames skipped)",
                self.malformed
            );
        }
        if self.truncated {
            out.push_str("(walker: the stream ends inside a frame)\n");
        }
        out
    }

    /// One line for the terminal.
    pub fn summary(&self) -> String {
        format!(
            "{} defmt lines ({} warnings/errors), {} malformed{}",
            self.lines.len(),
            self.warnings().count(),
            self.malformed,
            if self.truncated {
                ", cut at the end"
            } else {
                ""
            }
        )
    }
}

/// Decodes the raw defmt stream `raw` with the table of the ELF `elf`.
pub fn decode(elf: &[u8], raw: &[u8]) -> Result<DefmtLog, String> {
    let table = defmt_decoder::Table::parse(elf)
        .map_err(|e| format!("cannot read the ELF's defmt table: {e}"))?
        .ok_or("the ELF has no defmt table (built without defmt?)")?;
    // Locations need DWARF line info; without it the lines just have no location.
    let locations = table.get_locations(elf).unwrap_or_default();
    let can_recover = table.encoding().can_recover();
    let mut decoder = table.new_stream_decoder();
    decoder.received(raw);
    let mut log = DefmtLog::default();
    loop {
        match decoder.decode() {
            Ok(frame) => {
                let location = locations.get(&frame.index()).map(|l| {
                    let file = l.file.file_name().map_or_else(
                        || l.file.display().to_string(),
                        |f| f.to_string_lossy().into_owned(),
                    );
                    format!("{file}:{}", l.line)
                });
                log.lines.push(DefmtLine {
                    level: frame.level().map(|l| l.as_str()),
                    text: frame.display(false).to_string(),
                    location,
                });
            }
            Err(defmt_decoder::DecodeError::UnexpectedEof) => break,
            Err(defmt_decoder::DecodeError::Malformed) if can_recover => log.malformed += 1,
            Err(defmt_decoder::DecodeError::Malformed) => {
                // Raw encoding cannot resynchronise: the rest is lost.
                log.malformed += 1;
                return Ok(log);
            }
        }
    }
    // Whatever is left after the last frame: for rzCOBS a frame ends with a 0 byte.
    log.truncated = can_recover && raw.last().is_some_and(|b| *b != 0);
    Ok(log)
}

/// Decodes the raw stream file `raw` with `elf`'s table and writes the text log to `out`.
pub fn decode_file(elf: &Path, raw: &Path, out: &Path) -> Result<DefmtLog, String> {
    let elf_bytes =
        std::fs::read(elf).map_err(|e| format!("cannot read the ELF {}: {e}", elf.display()))?;
    let bytes = std::fs::read(raw)
        .map_err(|e| format!("cannot read the defmt stream {}: {e}", raw.display()))?;
    let log = decode(&elf_bytes, &bytes).map_err(|e| format!("{}: {e}", elf.display()))?;
    std::fs::write(out, log.text()).map_err(|e| format!("cannot write {}: {e}", out.display()))?;
    Ok(log)
}

/// Checks a decoded stream of `bytes` bytes from `raw` before its text is kept: refuses an
/// empty stream, one in which no frame decodes with the ELF's table (random bytes, another
/// build's ELF) and one with more malformed frames than decoded ones; warns of malformed
/// frames and of a stream cut inside a frame.
pub fn check(log: &DefmtLog, bytes: usize, raw: &Path) -> Result<Vec<String>, String> {
    let name = raw.display();
    if bytes == 0 {
        return Err(format!("the defmt stream {name} is empty (0 bytes)"));
    }
    if log.lines.is_empty() || log.malformed > log.lines.len() {
        return Err(format!(
            "the defmt stream {name} does not decode with this ELF's table ({bytes} bytes: {} frames decoded, {} malformed): not this firmware's defmt output (another build's ELF?)",
            log.lines.len(),
            log.malformed
        ));
    }
    let mut w = Vec::new();
    if log.malformed > 0 {
        w.push(format!(
            "the defmt stream {name}: {} malformed frames skipped",
            log.malformed
        ));
    }
    if log.truncated {
        w.push(format!(
            "the defmt stream {name} ends inside a frame (cut after {} lines)",
            log.lines.len()
        ));
    }
    Ok(w)
}

/// [`decode_file`] that refuses what [`check`] refuses (nothing written then); the text log
/// and the warnings.
pub fn decode_checked_file(
    elf: &Path,
    raw: &Path,
    out: &Path,
) -> Result<(DefmtLog, Vec<String>), String> {
    let elf_bytes =
        std::fs::read(elf).map_err(|e| format!("cannot read the ELF {}: {e}", elf.display()))?;
    let bytes = std::fs::read(raw)
        .map_err(|e| format!("cannot read the defmt stream {}: {e}", raw.display()))?;
    let log = decode(&elf_bytes, &bytes).map_err(|e| format!("{}: {e}", elf.display()))?;
    let warnings = check(&log, bytes.len(), raw)?;
    std::fs::write(out, log.text()).map_err(|e| format!("cannot write {}: {e}", out.display()))?;
    Ok((log, warnings))
}

#[cfg(test)]
mod tests {
    use super::*;
    use object::write::{Object, Symbol, SymbolSection};
    use object::{
        Architecture, BinaryFormat, Endianness, SectionKind, SymbolFlags, SymbolKind, SymbolScope,
    };

    /// An ELF with a defmt table as the defmt macros and linker script leave it: the format
    /// strings as JSON symbol names in `.defmt` (address = index), the version and encoding
    /// symbols.
    fn elf(encoding: &str, entries: &[(&str, &str)]) -> Vec<u8> {
        let mut obj = Object::new(BinaryFormat::Elf, Architecture::Arm, Endianness::Little);
        let sec = obj.add_section(Vec::new(), b".defmt".to_vec(), SectionKind::ReadOnlyData);
        obj.append_section_data(sec, &[0u8; 16], 1);
        let sym = |name: String, value: u64, section: SymbolSection| Symbol {
            name: name.into_bytes(),
            value,
            size: 1,
            kind: SymbolKind::Data,
            scope: SymbolScope::Linkage,
            weak: false,
            section,
            flags: SymbolFlags::None,
        };
        for (i, (tag, data)) in entries.iter().enumerate() {
            let json = format!(
                r#"{{"package":"walker-firmware","tag":"{tag}","data":"{data}","disambiguator":"{i}","crate_name":"walker_firmware"}}"#
            );
            obj.add_symbol(sym(json, i as u64 + 1, SymbolSection::Section(sec)));
        }
        obj.add_symbol(sym(
            "_defmt_version_ = 4".into(),
            1,
            SymbolSection::Absolute,
        ));
        obj.add_symbol(sym(
            format!("_defmt_encoding_ = {encoding}"),
            1,
            SymbolSection::Absolute,
        ));
        obj.write().unwrap()
    }

    const ENTRIES: [(&str, &str); 3] = [
        ("defmt_info", "boot {=u8} ok"),
        ("defmt_error", "device {=u8} lost after {=u16} ticks"),
        ("defmt_println", "plain"),
    ];

    /// A frame as defmt-semihosting sends it: rzCOBS, then a 0 separator.
    fn rz(payload: &[u8]) -> Vec<u8> {
        let mut f = rzcobs::encode(payload);
        f.push(0);
        f
    }

    #[test]
    fn frames_decode_with_the_elf_table() {
        let elf = elf("rzcobs", &ENTRIES);
        let mut raw = rz(&[1, 0, 42]);
        raw.extend(rz(&[2, 0, 111, 0x34, 0x12]));
        // A frame whose index is not in the table: skipped, the next one decodes.
        raw.extend(rz(&[9, 0]));
        raw.extend(rz(&[3, 0]));
        // The stream stops inside a frame.
        raw.extend(&rzcobs::encode(&[1, 0, 7])[..2]);
        let log = decode(&elf, &raw).unwrap();
        let texts: Vec<&str> = log.lines.iter().map(|l| l.text.as_str()).collect();
        assert_eq!(texts.len(), 3, "{texts:?}");
        assert!(
            texts[0].ends_with("boot 42 ok") && texts[0].contains("INFO"),
            "{texts:?}"
        );
        assert!(
            texts[1].ends_with("device 111 lost after 4660 ticks") && texts[1].contains("ERROR"),
            "{texts:?}"
        );
        assert_eq!(texts[2], "plain");
        let levels: Vec<Option<&str>> = log.lines.iter().map(|l| l.level).collect();
        assert_eq!(levels, [Some("info"), Some("error"), None]);
        assert_eq!(log.malformed, 1);
        assert!(log.truncated);
        assert_eq!(log.warnings().count(), 1);
        let text = log.text();
        assert!(text.contains("1 malformed defmt frames skipped"), "{text}");
        assert!(text.contains("ends inside a frame"), "{text}");
        assert_eq!(
            log.summary(),
            "3 defmt lines (1 warnings/errors), 1 malformed, cut at the end"
        );
    }

    #[test]
    fn garbage_and_empty_streams_are_refused() {
        let elf = elf("rzcobs", &ENTRIES);
        let p = Path::new("x.defmt");
        assert!(check(&decode(&elf, &[]).unwrap(), 0, p)
            .unwrap_err()
            .contains("is empty"));
        // Random bytes (xorshift): nothing decodes, or far more malformed than decoded.
        let mut x = 0x2545_F491_4F6C_DD1Du64;
        let random: Vec<u8> = (0..4096)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                (x >> 24) as u8
            })
            .collect();
        let log = decode(&elf, &random).unwrap();
        let e = check(&log, random.len(), p).unwrap_err();
        assert!(e.contains("does not decode with this ELF"), "{e}");
        // A good stream cut inside a frame: kept, with a warning.
        let mut raw = rz(&[1, 0, 42]);
        raw.extend(&rzcobs::encode(&[1, 0, 7])[..2]);
        let w = check(&decode(&elf, &raw).unwrap(), raw.len(), p).unwrap();
        assert_eq!(w.len(), 1);
        assert!(w[0].contains("ends inside a frame"), "{w:?}");
    }

    #[test]
    fn raw_encoding_and_bad_elves() {
        let elf_raw = elf("raw", &ENTRIES);
        let log = decode(&elf_raw, &[1, 0, 5, 3, 0]).unwrap();
        assert_eq!(log.lines.len(), 2);
        assert!(log.lines[0].text.ends_with("boot 5 ok"));
        assert!(!log.truncated && log.malformed == 0);
        // Raw frames cannot resynchronise: a bad index ends the decoding.
        let log = decode(&elf_raw, &[1, 0, 5, 9, 0, 1, 0, 6]).unwrap();
        assert_eq!((log.lines.len(), log.malformed), (1, 1));
        // An ELF without defmt, and bytes that are no ELF.
        let none = Object::new(BinaryFormat::Elf, Architecture::Arm, Endianness::Little)
            .write()
            .unwrap();
        assert!(decode(&none, &[]).unwrap_err().contains("no defmt table"));
        assert!(decode(b"not an elf", &[])
            .unwrap_err()
            .contains("cannot read the ELF's defmt table"));
    }
}
