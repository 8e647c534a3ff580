//! The integration tests, one binary so CI links once: command-line runs,
//! end-to-end service tests with the real `tslg-server` and `tslg-worker`
//! processes, and the dashboard in headless Chromium.

mod support;

mod architecture;
mod method_home;
mod module_graph;

mod browser_dashboard;
mod browser_kinds;
mod browser_support;
mod cli;
mod deploy_kubernetes;
mod docs_commands;
mod reproduce;
mod service_access;
mod service_adaptive;
mod service_adversarial;
mod service_anytime;
mod service_bad_input;
mod service_builds;
mod service_carfollow;
mod service_cli;
mod service_dashboard;
mod service_deploy;
mod service_e2e;
mod service_events;
mod service_evidence;
mod service_external;
mod service_fairness;
mod service_held_back;
mod service_highway;
mod service_leaving;
mod service_load;
mod service_long_poll;
mod service_next_lease;
mod service_noise;
mod service_outside;
mod service_paired;
mod service_principals;
mod service_protocol;
mod service_recovery;
mod service_scale;
mod service_slow;
mod service_slurm;
mod service_sumo;
mod service_trust;
mod service_upgrade;
mod service_user_case;
mod tables;
mod user_case;
