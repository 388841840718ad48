//! The integration tests, one binary with one module per topic, so that a change links once.
//! Run one topic with `cargo test --release --all-features --test it TOPIC::`.

mod common;

#[cfg(feature = "optimize")]
mod advtrain;
#[cfg(feature = "optimize")]
mod attack_crossval;
#[cfg(feature = "optimize")]
mod attack_optimize;
#[cfg(feature = "optimize")]
mod attack_step;
#[cfg(feature = "optimize")]
mod bake_fca;
mod blender_views;
mod capture_sim;
mod cli_evaluate;
mod cli_pav;
mod cli_rig;
mod config_reference;
#[cfg(feature = "eval")]
mod custom_layout;
mod custom_white_box;
mod darknet_onnx;
mod data_fetch;
#[cfg(feature = "eval")]
mod defences;
#[cfg(feature = "optimize")]
mod detector_config;
mod detectors_reference;
#[cfg(feature = "eval")]
mod detectors_wide;
mod docs;
#[cfg(feature = "doctor")]
mod doctor;
mod evaluate_fixture;
mod firmware_qemu;
mod grammar;
mod layers;
#[cfg(feature = "optimize")]
mod lofo;
#[cfg(feature = "eval")]
mod model_inspect;
mod names;
#[cfg(feature = "eval")]
mod ortgrad_darknet;
#[cfg(feature = "optimize")]
mod ortgrad_deimv2;
#[cfg(feature = "optimize")]
mod ortgrad_wide;
#[cfg(feature = "optimize")]
mod ortgrad_yolov8n;
#[cfg(feature = "eval")]
mod ortgrad_yolox;
mod print_charts;
mod print_pieces;
mod project;
mod render_fca;
mod render_impala;
mod results;
mod rig_shot;
#[cfg(feature = "optimize")]
mod slurm;
mod steps;
#[cfg(feature = "eval")]
mod surrogate;
mod turntable_sim;
mod wall_time;
#[cfg(feature = "optimize")]
mod whitebox_iou;
