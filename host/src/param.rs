//! `walker param`: the firmware's run-time parameters over its command port (the parameter
//! registers of `walker_contract::command_port`, docs/command-port.md "Parameters"): list,
//! get and set them by key, as `key=value` tokens — the semihosting command line's and the
//! plan's `[firmware]` table's form; save them to the board's store (loaded at its next boot).
//! A set or a save is refused while a run is going (the firmware serves them only while it
//! waits for the enable, `wait_enable`).

use std::time::{Duration, Instant};

use walker_contract::command_port::{
    ParamOp, ParamStatus, PARAM_COUNT, PARAM_INDEX, PARAM_KEY, PARAM_OP, PARAM_STATUS, PARAM_VALUE,
};

use crate::commands::PortMaster;

/// How long an op may stay pending (the firmware serves it at its next tick).
pub const OP_WAIT: Duration = Duration::from_secs(2);

/// How long a save may stay pending: a flash store erases a sector first (the OpenCR's 256 KiB
/// sectors take seconds, while which its command port does not answer).
pub const SAVE_WAIT: Duration = Duration::from_secs(30);

/// The command port as the parameter tool sees it.
pub trait ParamLink {
    /// WRITE `data` at `addr`, the status checked.
    fn write(&mut self, addr: u16, data: &[u8]) -> Result<(), String>;
    /// READ `len` bytes at `addr`.
    fn read(&mut self, addr: u16, len: u16) -> Result<Vec<u8>, String>;
}

impl ParamLink for PortMaster {
    fn write(&mut self, addr: u16, data: &[u8]) -> Result<(), String> {
        PortMaster::write(self, addr, data)
    }
    fn read(&mut self, addr: u16, len: u16) -> Result<Vec<u8>, String> {
        PortMaster::read(self, addr, len)
    }
}

/// Runs one op (key, value and op in one WRITE; for [`ParamOp::GetByIndex`] Param Index
/// first) and waits until it is served; its status.
fn run(
    link: &mut dyn ParamLink,
    key: &str,
    value: &str,
    op: ParamOp,
) -> Result<ParamStatus, String> {
    let (k, v) = (usize::from(PARAM_KEY.len), usize::from(PARAM_VALUE.len));
    if key.len() > k || value.len() > v || !key.is_ascii() || !value.is_ascii() {
        return Err(format!(
            "`{key}={value}`: the key takes at most {k} ASCII bytes, the value {v}"
        ));
    }
    let mut data = vec![0u8; k + v + 1];
    data[..key.len()].copy_from_slice(key.as_bytes());
    data[k..k + value.len()].copy_from_slice(value.as_bytes());
    data[k + v] = op.code();
    link.write(PARAM_KEY.addr, &data)?;
    let wait = if op == ParamOp::Save {
        SAVE_WAIT
    } else {
        OP_WAIT
    };
    let start = Instant::now();
    loop {
        // A read that fails while the op may still be pending is asked again (the board may
        // be deaf while it serves it).
        let s = match link.read(PARAM_STATUS.addr, 1) {
            Ok(s) => s,
            Err(_) if start.elapsed() < wait => {
                std::thread::sleep(Duration::from_millis(20));
                continue;
            }
            Err(e) => return Err(e),
        };
        let status = s
            .first()
            .and_then(|&c| ParamStatus::try_from(c).ok())
            .ok_or_else(|| format!("Param Status {s:?}: not a status"))?;
        if status != ParamStatus::Pending {
            return Ok(status);
        }
        if start.elapsed() >= wait {
            return Err(format!("`{key}`: not served within {} s", wait.as_secs()));
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// The text of a NUL-padded register.
fn text(b: &[u8]) -> String {
    let n = b.iter().position(|&c| c == 0).unwrap_or(b.len());
    String::from_utf8_lossy(&b[..n]).into_owned()
}

/// The value in force of `key`, as token text (empty: the key is not set).
pub fn get(link: &mut dyn ParamLink, key: &str) -> Result<String, String> {
    match run(link, key, "", ParamOp::Get)? {
        ParamStatus::Done => Ok(text(&link.read(PARAM_VALUE.addr, PARAM_VALUE.len)?)),
        s => Err(format!("`{key}`: {}", s.reason())),
    }
}

/// Sets `key` to `value` (for the next run).
pub fn set(link: &mut dyn ParamLink, key: &str, value: &str) -> Result<(), String> {
    match run(link, key, value, ParamOp::Set)? {
        ParamStatus::Done => Ok(()),
        s => Err(format!("`{key}={value}`: {}", s.reason())),
    }
}

/// Saves the configuration in force to the board's store (loaded at its next boot; between
/// runs only).
pub fn save(link: &mut dyn ParamLink) -> Result<(), String> {
    match run(link, "", "", ParamOp::Save)? {
        ParamStatus::Done => Ok(()),
        s => Err(format!("save: {}", s.reason())),
    }
}

/// Every parameter's key and value, in the table's order.
pub fn list(link: &mut dyn ParamLink) -> Result<Vec<(String, String)>, String> {
    let c = link.read(PARAM_COUNT.addr, PARAM_COUNT.len)?;
    let count = match c.as_slice() {
        [a, b] => u16::from_le_bytes([*a, *b]),
        _ => return Err(format!("Param Count {c:?}")),
    };
    let mut out = Vec::with_capacity(usize::from(count));
    for i in 0..count {
        link.write(PARAM_INDEX.addr, &i.to_le_bytes())?;
        link.write(PARAM_OP.addr, &[ParamOp::GetByIndex.code()])?;
        let start = Instant::now();
        loop {
            let s = link.read(PARAM_STATUS.addr, 1)?;
            match s.first().and_then(|&c| ParamStatus::try_from(c).ok()) {
                Some(ParamStatus::Pending) if start.elapsed() < OP_WAIT => {
                    std::thread::sleep(Duration::from_millis(5))
                }
                Some(ParamStatus::Done) => break,
                Some(ParamStatus::Pending) => {
                    return Err(format!(
                        "parameter {i}: not served within {} s",
                        OP_WAIT.as_secs()
                    ))
                }
                Some(other) => return Err(format!("parameter {i}: {}", other.reason())),
                None => return Err(format!("parameter {i}: Param Status {s:?}: not a status")),
            }
        }
        let key = text(&link.read(PARAM_KEY.addr, PARAM_KEY.len)?);
        let value = text(&link.read(PARAM_VALUE.addr, PARAM_VALUE.len)?);
        out.push((key, value));
    }
    Ok(out)
}

/// Every parameter's value text in the configuration of `tokens` applied over the
/// firmware's defaults (the firmware's parser: a bad token is an error), in the table's order.
pub fn expected(tokens: &[String]) -> Result<Vec<(String, String)>, String> {
    let mut cfg = walker_contract::Config::default();
    let line = format!("walker {}", tokens.join(" "));
    walker_contract::params::apply(&mut cfg, line.as_bytes()).map_err(|e| e.to_string())?;
    Ok(walker_contract::params::PARAMS
        .iter()
        .map(|p| {
            let mut v = String::new();
            if let Some(x) = p.value(&cfg) {
                let _ = p.write_value(x, &mut v);
            }
            (p.key.to_string(), v)
        })
        .collect())
}

/// The keys whose values differ: (key, the firmware's, the expected), in `firmware`'s order;
/// a key missing on either side counts as differing (an empty value).
pub fn diff(
    firmware: &[(String, String)],
    expected: &[(String, String)],
) -> Vec<(String, String, String)> {
    let find = |list: &[(String, String)], k: &str| {
        list.iter()
            .find(|(key, _)| key == k)
            .map_or(String::new(), |(_, v)| v.clone())
    };
    let mut keys: Vec<&str> = firmware.iter().map(|(k, _)| k.as_str()).collect();
    for (k, _) in expected {
        if !keys.contains(&k.as_str()) {
            keys.push(k);
        }
    }
    keys.into_iter()
        .filter_map(|k| {
            let (f, e) = (find(firmware, k), find(expected, k));
            (f != e).then(|| (k.to_string(), f, e))
        })
        .collect()
}

/// Splits `key=value`.
pub fn split_token(t: &str) -> Result<(&str, &str), String> {
    t.split_once('=')
        .filter(|(k, _)| !k.is_empty())
        .ok_or_else(|| format!("`{t}`: expected key=value"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use walker_contract::command_port::{CommandTable, ParamAccess};
    use walker_contract::Config;

    /// The contract's table served after every write, as the firmware does at its tick:
    /// between runs (`running` false) or during one.
    struct Firmware {
        table: CommandTable,
        cfg: Config,
        running: bool,
        store_ok: bool,
        saves: usize,
        /// Status reads left unanswered (a board busy erasing its flash).
        deaf: usize,
        /// A build without the parameters (the OpenCM 9.04's): every op answered unsupported.
        unsupported: bool,
    }

    impl ParamLink for Firmware {
        fn write(&mut self, addr: u16, data: &[u8]) -> Result<(), String> {
            self.table.write(addr, data).map_err(|e| format!("{e:?}"))?;
            if self.unsupported {
                self.table.answer_param(ParamStatus::Unsupported);
                return Ok(());
            }
            let access = if self.running {
                ParamAccess::ReadOnly(&self.cfg)
            } else {
                ParamAccess::Settable(&mut self.cfg)
            };
            self.table.serve_param(access);
            if self.table.take_save() {
                self.saves += 1;
                self.table.finish_save(self.store_ok);
            }
            Ok(())
        }
        fn read(&mut self, addr: u16, len: u16) -> Result<Vec<u8>, String> {
            if self.deaf > 0 {
                self.deaf -= 1;
                return Err("no status packet".into());
            }
            self.table
                .read(addr, len)
                .map(<[u8]>::to_vec)
                .map_err(|e| format!("{e:?}"))
        }
    }

    fn firmware(running: bool) -> Firmware {
        Firmware {
            table: CommandTable::new(),
            cfg: Config::default(),
            running,
            store_ok: true,
            saves: 0,
            deaf: 0,
            unsupported: false,
        }
    }

    #[test]
    fn a_build_without_parameters_says_so_for_every_op() {
        let mut f = firmware(false);
        f.unsupported = true;
        let why = "not in this board's build";
        let e = get(&mut f, "catch_gain").unwrap_err();
        assert!(e.contains(why), "{e}");
        let e = set(&mut f, "catch_gain", "0.5").unwrap_err();
        assert!(e.contains(why), "{e}");
        let e = save(&mut f).unwrap_err();
        assert!(e.contains(why), "{e}");
        let e = list(&mut f).unwrap_err();
        assert_eq!(e, format!("parameter 0: {why}"));
        assert_eq!(format!("{:?}", f.cfg), format!("{:?}", Config::default()));
        assert_eq!(f.saves, 0);
    }

    #[test]
    fn set_get_and_list_round_trip_and_refusals_say_why() {
        let mut f = firmware(false);
        set(&mut f, "catch_gain", "0.5").unwrap();
        set(&mut f, "gyro_ankle", "0.03").unwrap();
        assert_eq!(get(&mut f, "catch_gain").unwrap(), "0.5");
        assert_eq!(get(&mut f, "gyro_ankle").unwrap(), "0.03");
        let mut direct = Config::default();
        walker_contract::params::apply(&mut direct, b"elf catch_gain=0.5 gyro_ankle=0.03").unwrap();
        assert_eq!(format!("{:?}", f.cfg), format!("{direct:?}"));
        let all = list(&mut f).unwrap();
        assert_eq!(all.len(), walker_contract::params::PARAMS.len());
        assert!(
            all.contains(&("catch_gain".into(), "0.5".into())),
            "{all:?}"
        );
        // Every listed value parses back to itself (the list is a valid command line).
        let line: Vec<String> = all
            .iter()
            .filter(|(_, v)| !v.is_empty())
            .map(|(k, v)| format!("{k}={v}"))
            .collect();
        let mut again = Config::default();
        walker_contract::params::apply(&mut again, format!("elf {}", line.join(" ")).as_bytes())
            .unwrap();
        assert_eq!(format!("{again:?}"), format!("{:?}", f.cfg));
        let e = set(&mut f, "catch_gain", "9").unwrap_err();
        assert!(e.contains("out of range"), "{e}");
        let e = get(&mut f, "no_such").unwrap_err();
        assert!(e.contains("unknown key"), "{e}");
        assert!(set(&mut f, &"k".repeat(25), "1").is_err());
        let mut r = firmware(true);
        let e = set(&mut r, "catch_gain", "0.5").unwrap_err();
        assert!(e.contains("refused while a run is going"), "{e}");
        assert_eq!(format!("{:?}", r.cfg), format!("{:?}", Config::default()));
        assert_eq!(split_token("a=b=c").unwrap(), ("a", "b=c"));
        // Diff: the firmware's list against the defaults and against the tokens it was given.
        let mut f = firmware(false);
        set(&mut f, "catch_gain", "0.5").unwrap();
        let now = list(&mut f).unwrap();
        let d = diff(&now, &expected(&[]).unwrap());
        assert_eq!(d.len(), 1, "{d:?}");
        assert_eq!((d[0].0.as_str(), d[0].1.as_str()), ("catch_gain", "0.5"));
        assert!(diff(&now, &expected(&["catch_gain=0.5".into()]).unwrap()).is_empty());
        assert!(expected(&["catch_gain=9".into()]).is_err());
        assert!(split_token("=1").is_err() && split_token("a").is_err());
        // Save: done, refused during a run, or the store's failure.
        let mut f = firmware(false);
        save(&mut f).unwrap();
        // A board deaf for a few reads while it saves (a flash erase) is waited for.
        f.deaf = 5;
        save(&mut f).unwrap();
        assert_eq!((f.saves, f.deaf), (2, 0));
        f.store_ok = false;
        assert!(save(&mut f).unwrap_err().contains("the store failed"));
        let mut r = firmware(true);
        assert!(save(&mut r)
            .unwrap_err()
            .contains("refused while a run is going"));
        assert_eq!(r.saves, 0);
    }
}
