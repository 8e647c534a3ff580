//! The external-vehicle messages carry everything a vehicle needs: a
//! program double that receives every message as JSON text (as over a
//! pipe) and hands what it carries to a built-in model gives exactly the
//! built-in model's outcomes and weights, test for test, in every case and
//! both modes.

use serde_json::{json, Value};
use tslg_method::cases::carfollow::highway_vehicle;
use tslg_method::cases::cutin::CutInPreset;
use tslg_method::cases::highway::drivers::{Driver, DriverView, Lane};
use tslg_method::cases::highway::external::RIGHT_LANE;
use tslg_method::cases::highway::world::{ExitWorld, Traffic};
use tslg_method::cases::highway::{simulation, ExitVehicle};
use tslg_method::cases::open_case;
use tslg_method::external::{
    Control, DriverError, EpisodeOutcome, ExternalVehicle, Observation, TestStart,
};
use tslg_method::registry::{BuildRequest, CampaignTests, ExposureSource};
use tslg_method::sampling::OutsideSpread;
use tslg_method::vehicle::{Controller, FollowerObservation, VehicleModel};

/// The models the double stands in for, per case.
fn cut_in_model() -> VehicleModel {
    VehicleModel::builtin("idm").unwrap()
}

fn exit_model() -> ExitVehicle {
    ExitVehicle::builtin("mobil").unwrap()
}

enum Memory {
    Follow {
        controller: Controller,
        clip: (f64, f64),
        dt: f64,
    },
    Exit(Driver),
}

/// A program double: parses each message from its JSON text, acts with a
/// fresh built-in model after each reset, and answers in JSON text.
#[derive(Default)]
struct Mirror {
    case: String,
    memory: Option<Memory>,
    next_step: u32,
    resets: u64,
    steps: u64,
}

fn through_json<T: serde::Serialize + serde::de::DeserializeOwned>(value: &T) -> T {
    serde_json::from_str(&serde_json::to_string(value).unwrap()).unwrap()
}

fn pair(v: &Value) -> (f64, f64) {
    (v[0].as_f64().unwrap(), v[1].as_f64().unwrap())
}

impl ExternalVehicle for Mirror {
    fn reset(&mut self, start: &TestStart) -> Result<(), DriverError> {
        let start: Value = serde_json::from_str(&serde_json::to_string(start).unwrap()).unwrap();
        self.case = start["case"].as_str().unwrap().to_owned();
        let world = &start["world"];
        let follow = |controller: Controller| Memory::Follow {
            controller,
            clip: pair(&world["acceleration"]),
            dt: world["dt"].as_f64().unwrap(),
        };
        self.memory = Some(match self.case.as_str() {
            "cut-in" => follow(cut_in_model().controller()),
            "car-following" => follow(highway_vehicle("idm").unwrap().controller()),
            "highway-exit" => Memory::Exit(exit_model().driver()),
            other => panic!("unknown case {other}"),
        });
        self.next_step = 0;
        self.resets += 1;
        Ok(())
    }

    fn step(&mut self, observation: &Observation) -> Result<Control, DriverError> {
        let o = through_json(observation);
        assert_eq!(o.step, self.next_step, "steps count from 0 after a reset");
        self.next_step += 1;
        self.steps += 1;
        let control = match self.memory.as_mut().expect("a reset before the first step") {
            Memory::Follow {
                controller,
                clip,
                dt,
            } => {
                let lead = o.vehicles.iter().find(|v| v.gap.is_some()).unwrap();
                let obs = FollowerObservation {
                    speed: o.ego.speed,
                    lead_speed: lead.speed,
                    gap: lead.gap.unwrap(),
                };
                Control {
                    acceleration: controller.acceleration(&obs, *clip, *dt),
                    change_lane: false,
                }
            }
            Memory::Exit(driver) => {
                let [a, b] = [&o.vehicles[0], &o.vehicles[1]];
                let traffic = Traffic::new([a.position, a.speed, b.position, b.speed]);
                let action = driver.act(&DriverView {
                    world: &ExitWorld::paper(),
                    time: o.time,
                    position: o.ego.position,
                    speed: o.ego.speed,
                    lane: if o.ego.lane == RIGHT_LANE {
                        Lane::Right
                    } else {
                        Lane::Left
                    },
                    traffic: &traffic,
                });
                Control {
                    acceleration: action.accel,
                    change_lane: action.change_lane,
                }
            }
        };
        Ok(through_json(&control))
    }

    fn episode(&mut self, scenario: &Value) -> Result<EpisodeOutcome, DriverError> {
        let x: Value = through_json(scenario);
        let event = match self.case.as_str() {
            "cut-in" => {
                let (r, rd) = (
                    x["range"].as_f64().unwrap(),
                    x["range_rate"].as_f64().unwrap(),
                );
                CutInPreset::PaperCode
                    .settings()
                    .run(&cut_in_model(), r, rd, 100.0)
                    .accident
            }
            "highway-exit" => {
                let x = ["p1", "v1", "p2", "v2"].map(|k| x[k].as_f64().unwrap());
                simulation::run(&ExitWorld::paper(), &exit_model(), x)
                    .outcome
                    .is_failure()
            }
            other => panic!("no episodes in {other}"),
        };
        Ok(through_json(&EpisodeOutcome {
            event,
            criticality: None,
            note: None,
        }))
    }
}

/// Runs `tests` on the built-in model and through the double; both must
/// agree exactly. Returns the events seen.
fn agree(builtin: &dyn CampaignTests, program: &dyn CampaignTests, n: u64) -> usize {
    let mut mirror = Mirror::default();
    let mut events = 0;
    for index in 0..n {
        let expected = builtin.run(index);
        let got = program.run_with(index, Some(&mut mirror)).unwrap();
        assert_eq!(got, expected, "test {index}");
        events += usize::from(expected.event);
        if expected.event {
            assert_eq!(program.check_event(index, got.weight), Ok(()));
        }
    }
    assert_eq!(mirror.resets, n, "one reset per test");
    events
}

/// Runs the cells of `tests`' first `n` tests as an adaptive campaign's
/// lease names them, on the built-in model and through the double: the same
/// events, and in step mode the same criticality, which the case measures
/// as it drives the program (in episode mode this double sends none).
fn agree_on_cells(builtin: &dyn CampaignTests, program: &dyn CampaignTests, mode: &str, n: u64) {
    let mut mirror = Mirror::default();
    for index in 0..n {
        let cell = builtin.planned(index).unwrap().cell;
        let (event, criticality) = builtin.run_cell(index, cell, None).unwrap();
        let (got, measured) = program.run_cell(index, cell, Some(&mut mirror)).unwrap();
        assert_eq!(got, event, "test {index}");
        match mode {
            "step" => assert_eq!(
                measured.map(f64::to_bits),
                criticality.map(f64::to_bits),
                "test {index}"
            ),
            _ => assert_eq!(measured, None),
        }
    }
    assert_eq!(mirror.resets, n, "one reset per test");
}

#[test]
fn cut_in_in_step_and_episode_mode_matches_the_builtin_model() {
    let case = open_case("cut-in", None, &ExposureSource::Builtin).unwrap();
    let built = case
        .build_library(&json!({"model": "idm"}), &BuildRequest::default())
        .unwrap();
    let campaign = |vut: Value| {
        case.campaign(
            Some(&built.file),
            &vut,
            0.1,
            OutsideSpread::Uniform,
            Default::default(),
            11,
        )
        .unwrap()
    };
    let builtin = campaign(json!({"model": "idm"}));
    for mode in ["step", "episode"] {
        let program = campaign(json!({"external": "mirror", "mode": mode}));
        assert_eq!(program.external().unwrap().external, "mirror");
        let events = agree(builtin.as_ref(), program.as_ref(), 1500);
        assert!(events > 100, "{mode}: {events} events");
        agree_on_cells(builtin.as_ref(), program.as_ref(), mode, 300);
    }
}

#[test]
fn highway_exit_in_step_and_episode_mode_matches_the_builtin_model() {
    let case = open_case("highway-exit", Some("coarse"), &ExposureSource::Builtin).unwrap();
    let built = case
        .build_library(&json!({"model": "mobil"}), &BuildRequest::default())
        .unwrap();
    let campaign = |vut: Value| {
        case.campaign(
            Some(&built.file),
            &vut,
            0.1,
            OutsideSpread::Uniform,
            Default::default(),
            2,
        )
        .unwrap()
    };
    let builtin = campaign(json!({"model": "mobil"}));
    for mode in ["step", "episode"] {
        let program = campaign(json!({"external": "mirror", "mode": mode}));
        let events = agree(builtin.as_ref(), program.as_ref(), 400);
        assert!(events > 5, "{mode}: {events} failures");
        agree_on_cells(builtin.as_ref(), program.as_ref(), mode, 200);
    }
}

#[test]
fn car_following_in_step_mode_matches_the_builtin_model_and_is_not_replayed() {
    let case = open_case("car-following", Some("risky"), &ExposureSource::Builtin).unwrap();
    let built = case
        .build_library(&json!({"model": "idm"}), &BuildRequest::default())
        .unwrap();
    let campaign = |vut: Value| {
        case.campaign(
            Some(&built.file),
            &vut,
            0.1,
            OutsideSpread::Ndd,
            Default::default(),
            4,
        )
        .unwrap()
    };
    let builtin = campaign(json!({"model": "idm"}));
    let program = campaign(json!({"external": "mirror"}));
    let events = agree(builtin.as_ref(), program.as_ref(), 300);
    assert!(events > 20, "{events} accidents");
    // The coordinator cannot replay a program: a non-accident passes its
    // check, which only bounds the weight.
    assert_eq!(program.check_event(0, 0.5), Ok(()));
    assert!(program.check_event(0, f64::INFINITY).is_err());
    assert!(builtin.check_event(0, 0.5).is_err() || builtin.run(0).event);
    // Without a program an external campaign cannot run a test.
    let err = program.run_with(0, None).unwrap_err();
    assert!(err.0.contains("external program `mirror`"), "{err}");
    // Episode mode does not exist here, and exact answers and libraries
    // need built-in models.
    let err = case
        .normalise_vehicle(&json!({"external": "mirror", "mode": "episode"}))
        .unwrap_err();
    assert!(err.to_string().contains("step mode only"), "{err}");
    let err = case
        .build_library(&json!({"external": "mirror"}), &BuildRequest::default())
        .unwrap_err();
    assert!(err.to_string().contains("needs a built-in model"), "{err}");
    assert_eq!(
        case.normalise_vehicle(&json!({"external": "mirror"}))
            .unwrap(),
        json!({"external": "mirror", "mode": "step"})
    );
}
