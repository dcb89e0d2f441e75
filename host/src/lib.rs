//! walker-host: host tools for the walking controller.

pub mod ablation;
pub mod beyond;
pub mod capture;
pub mod cli;
pub mod commands;
pub mod defmt_log;
pub mod drive;
pub mod export;
pub mod fil;
pub mod mcap_export;
pub mod opencm_boot;
pub mod opencr_boot;
pub mod param;
pub mod planfile;
pub mod plot;
pub mod progress;
pub mod pushes;
pub mod qemu;
pub mod report;
pub mod runconfig;
pub mod sim;
pub mod speed;
pub mod sweep;
pub mod video;
