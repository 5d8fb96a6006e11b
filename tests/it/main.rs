//! The integration tests, in one crate (issue 41): one binary to build and
//! link instead of one per topic. Each module is a topic (a former
//! `tests/<topic>.rs`); run one with
//! `cargo test --release --test it <topic>::`, or one test with
//! `cargo test --release --test it <topic>::<test name>`.
//!
//! A test that needs a process to itself is its own binary, declared in
//! Cargo.toml beside this one (`autotests = false`: a new file in `tests/`
//! is built only once it is declared here or there, which `layout` checks):
//! `tests/signal_race.rs`, whose signals are timed against a window it
//! measures first, so it runs alone rather than beside other tests' work;
//! `tests/memory_estimates.rs`, whose `#[global_allocator]` counts every
//! allocation of its process.
//!
//! `common` (`tests/common/`) holds the helpers the topics share; the
//! separate binaries and the benches include it too.

#[path = "../common/mod.rs"]
mod common;

mod bake;
mod bangay_morkel;
mod cache;
mod channels;
mod cli_errors;
mod clone_alone;
mod coherent;
mod configs_on_other_meshes;
mod hostile_inputs;
mod image_metrics;
mod jump_map;
mod jump_surface;
mod lapped;
mod layout;
mod logs_and_api;
mod max_flow;
mod memory;
mod memory_limits;
mod mesh_io;
mod messy_scans;
mod outputs_conventions;
mod peer;
mod pipeline;
mod plane;
mod positions_and_components;
mod progress;
mod quality_metrics;
mod render;
mod retile;
mod retile_map_back;
mod retile_stage;
mod run_atomicity;
mod subdivision;
mod sweep;
mod texture_scale;
mod up_front;
mod viewer;
mod wei_levoy;
