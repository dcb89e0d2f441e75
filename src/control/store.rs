//! The saved parameters on the board's store ([`walker_contract::param_store`]: two
//! CRC-checked copies): loaded once at boot by [`super::run_on_enable`], saved on the command
//! port's save op while the firmware waits for the enable. The slot buffers (4 KiB each) live
//! on the stack of these calls only, beside the runs, never inside them.

use walker_contract::param_store::{self, StoreOutcome, SLOT_LEN};

use crate::board::Board;
use crate::Config;

/// Loads the newest valid copy into `cfg` (the defaults stay when none loads); what it found.
pub fn load<B: Board>(board: &mut B, cfg: &mut Config) -> StoreOutcome {
    let mut a = [0xFFu8; SLOT_LEN];
    let mut b = [0xFFu8; SLOT_LEN];
    if !board.store_read(0, &mut a) || !board.store_read(1, &mut b) {
        return StoreOutcome::NoStore;
    }
    param_store::load(cfg, [&a, &b])
}

/// Saves `cfg` into the slot that does not hold the newest copy; true when written.
pub fn save<B: Board>(board: &mut B, cfg: &Config) -> bool {
    let mut a = [0xFFu8; SLOT_LEN];
    let mut b = [0xFFu8; SLOT_LEN];
    if !board.store_read(0, &mut a) || !board.store_read(1, &mut b) {
        return false;
    }
    let (slot, seq) = param_store::next_save([&a, &b]);
    // The buffer of the slot about to be overwritten takes the new copy.
    let out = if slot == 0 { &mut a } else { &mut b };
    match param_store::encode(cfg, seq, out) {
        Some(n) => out.get(..n).is_some_and(|d| board.store_write(slot, d)),
        None => false,
    }
}
