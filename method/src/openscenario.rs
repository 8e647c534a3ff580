//! A grid case's scenario as an ASAM OpenSCENARIO 1.0 file (`.xosc`) that
//! another simulator can replay: the vehicles, their initial lanes,
//! positions and speeds, the scripted lane change, and when the run ends.
//! Each case says what its cell means ([`crate::case::Case::openscenario`]);
//! this module writes the XML, in the element order the 1.0 schema demands
//! (checked against the official XSD by `scripts/check-xosc` in the tests).
//!
//! The road is [`ROAD_FILE`], a straight road written by
//! [`straight_road_xodr`] (OpenDRIVE 1.7): two driving lanes of 3.5 m in
//! the direction of increasing `s`, lane −1 the left one (next to the centre
//! line) and −2 the right one, as in right-hand traffic.
//!
//! Positions are along the road (`s`, m) and refer to a vehicle's rear end:
//! its bounding box's centre lies half a length ahead, so a vehicle at `s`
//! spans `[s, s + length]` and the bumper gap to a vehicle ahead at `s'` is
//! `s' − s − length`.

use std::fmt::Write;

/// The road file every scenario names, written beside the scenarios.
pub const ROAD_FILE: &str = "tslg_straight_road.xodr";
/// The road's length (m): every case's scenario fits on it.
pub const ROAD_LENGTH: f64 = 2000.0;
/// The left lane's OpenDRIVE id.
pub const LEFT_LANE: i32 = -1;
/// The right lane's OpenDRIVE id.
pub const RIGHT_LANE: i32 = -2;

/// One vehicle at the start of the scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct PlacedVehicle {
    /// The entity's name; the vehicle under test is `Ego`.
    pub name: &'static str,
    /// Its lane ([`LEFT_LANE`] or [`RIGHT_LANE`]).
    pub lane: i32,
    /// Its rear end along the road (m).
    pub s: f64,
    /// Its speed (m/s).
    pub speed: f64,
    /// Its length (m).
    pub length: f64,
}

/// A lane change that starts with the scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct LaneChange {
    /// Who changes lane.
    pub actor: &'static str,
    /// The lane it changes to.
    pub target_lane: i32,
    /// How long it takes (s); 0: at once (a step).
    pub duration: f64,
}

/// One scenario, ready to write.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// What it is, in words (the file header's description).
    pub description: String,
    /// The vehicles, the vehicle under test first.
    pub vehicles: Vec<PlacedVehicle>,
    /// The scripted lane change, if any.
    pub lane_change: Option<LaneChange>,
    /// The run ends after this long (s) …
    pub max_time: f64,
    /// … or when this vehicle's rear end reaches `s` (a goal, e.g. the exit).
    pub goal: Option<(&'static str, f64)>,
}

/// `&`, `<`, `>`, `"` and `'` as XML entities.
fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
        .replace('\'', "&apos;")
}

/// A number as `xsd:double` reads it (Rust's shortest round-trip form; the
/// scenes never hold infinities or NaN).
fn number(value: f64) -> String {
    debug_assert!(value.is_finite());
    format!("{value}")
}

fn vehicle(xml: &mut String, v: &PlacedVehicle) {
    let half = number(v.length / 2.0);
    let _ = write!(
        xml,
        r#"    <ScenarioObject name="{name}">
      <Vehicle name="{name}" vehicleCategory="car">
        <ParameterDeclarations/>
        <BoundingBox><Center x="{half}" y="0" z="0.75"/><Dimensions width="1.8" length="{length}" height="1.5"/></BoundingBox>
        <Performance maxSpeed="70" maxAcceleration="10" maxDeceleration="10"/>
        <Axles>
          <FrontAxle maxSteering="0.5" wheelDiameter="0.6" trackWidth="1.6" positionX="{front}" positionZ="0.3"/>
          <RearAxle maxSteering="0" wheelDiameter="0.6" trackWidth="1.6" positionX="{rear}" positionZ="0.3"/>
        </Axles>
        <Properties/>
      </Vehicle>
    </ScenarioObject>
"#,
        name = v.name,
        length = number(v.length),
        front = number(v.length * 0.8),
        rear = number(v.length * 0.2),
    );
}

fn initial_state(xml: &mut String, v: &PlacedVehicle) {
    let _ = write!(
        xml,
        r#"        <Private entityRef="{name}">
          <PrivateAction><TeleportAction><Position><LanePosition roadId="1" laneId="{lane}" offset="0" s="{s}"/></Position></TeleportAction></PrivateAction>
          <PrivateAction><LongitudinalAction><SpeedAction>
            <SpeedActionDynamics dynamicsShape="step" value="0" dynamicsDimension="time"/>
            <SpeedActionTarget><AbsoluteTargetSpeed value="{speed}"/></SpeedActionTarget>
          </SpeedAction></LongitudinalAction></PrivateAction>
        </Private>
"#,
        name = v.name,
        lane = v.lane,
        s = number(v.s),
        speed = number(v.speed),
    );
}

/// A trigger when the simulation time passes `time`.
fn after(name: &str, time: f64) -> String {
    format!(
        r#"<ConditionGroup><Condition name="{name}" delay="0" conditionEdge="none"><ByValueCondition><SimulationTimeCondition value="{}" rule="greaterThan"/></ByValueCondition></Condition></ConditionGroup>"#,
        number(time)
    )
}

fn story(xml: &mut String, change: Option<&LaneChange>) {
    // OpenSCENARIO 1.0 demands a story; without a lane change it holds an
    // act with no events beyond keeping the start.
    let Some(change) = change else {
        let _ = write!(
            xml,
            r#"    <Story name="Scenario">
      <Act name="Start">
        <ManeuverGroup name="Nothing" maximumExecutionCount="1"><Actors selectTriggeringEntities="false"/></ManeuverGroup>
        <StartTrigger>{}</StartTrigger>
      </Act>
    </Story>
"#,
            after("ActStart", 0.0)
        );
        return;
    };
    let shape = if change.duration > 0.0 {
        "sinusoidal"
    } else {
        "step"
    };
    let _ = write!(
        xml,
        r#"    <Story name="Scenario">
      <Act name="LaneChange">
        <ManeuverGroup name="LaneChangeGroup" maximumExecutionCount="1">
          <Actors selectTriggeringEntities="false"><EntityRef entityRef="{actor}"/></Actors>
          <Maneuver name="LaneChangeManeuver">
            <Event name="LaneChangeEvent" priority="overwrite" maximumExecutionCount="1">
              <Action name="LaneChange"><PrivateAction><LateralAction><LaneChangeAction>
                <LaneChangeActionDynamics dynamicsShape="{shape}" value="{duration}" dynamicsDimension="time"/>
                <LaneChangeTarget><AbsoluteTargetLane value="{lane}"/></LaneChangeTarget>
              </LaneChangeAction></LateralAction></PrivateAction></Action>
              <StartTrigger>{start}</StartTrigger>
            </Event>
          </Maneuver>
        </ManeuverGroup>
        <StartTrigger>{act}</StartTrigger>
      </Act>
    </Story>
"#,
        actor = change.actor,
        duration = number(change.duration),
        lane = change.target_lane,
        start = after("LaneChangeStart", 0.0),
        act = after("ActStart", 0.0),
    );
}

fn stop(xml: &mut String, max_time: f64, goal: Option<(&'static str, f64)>) {
    let mut groups = after("TimeUp", max_time);
    if let Some((entity, s)) = goal {
        let _ = write!(
            groups,
            r#"<ConditionGroup><Condition name="Goal" delay="0" conditionEdge="none"><ByEntityCondition><TriggeringEntities triggeringEntitiesRule="any"><EntityRef entityRef="{entity}"/></TriggeringEntities><EntityCondition><ReachPositionCondition tolerance="1"><Position><LanePosition roadId="1" laneId="{RIGHT_LANE}" offset="0" s="{}"/></Position></ReachPositionCondition></EntityCondition></ByEntityCondition></Condition></ConditionGroup>"#,
            number(s)
        );
    }
    let _ = writeln!(xml, "    <StopTrigger>{groups}</StopTrigger>");
}

impl Scene {
    /// The scene as an OpenSCENARIO 1.0 document.
    pub fn to_xosc(&self) -> String {
        let mut xml = format!(
            r#"<?xml version="1.0" encoding="UTF-8"?>
<OpenSCENARIO>
  <FileHeader revMajor="1" revMinor="0" date="2026-01-01T00:00:00" description="{}" author="tslg"/>
  <ParameterDeclarations/>
  <CatalogLocations/>
  <RoadNetwork><LogicFile filepath="{ROAD_FILE}"/></RoadNetwork>
  <Entities>
"#,
            escape(&self.description)
        );
        for v in &self.vehicles {
            vehicle(&mut xml, v);
        }
        xml.push_str("  </Entities>\n  <Storyboard>\n    <Init><Actions>\n");
        for v in &self.vehicles {
            initial_state(&mut xml, v);
        }
        xml.push_str("    </Actions></Init>\n");
        story(&mut xml, self.lane_change.as_ref());
        stop(&mut xml, self.max_time, self.goal);
        xml.push_str("  </Storyboard>\n</OpenSCENARIO>\n");
        xml
    }
}

/// [`ROAD_FILE`]: a straight road of [`ROAD_LENGTH`] with the two driving
/// lanes, as OpenDRIVE 1.7.
pub fn straight_road_xodr() -> String {
    let lane = |id: i32, mark: &str| {
        format!(
            r#"          <lane id="{id}" type="driving" level="false"><link/><width sOffset="0" a="3.5" b="0" c="0" d="0"/><roadMark sOffset="0" type="{mark}" weight="standard" color="standard" width="0.12"/></lane>
"#
        )
    };
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<OpenDRIVE>
  <header revMajor="1" revMinor="7" name="tslg straight road" version="1" north="0" south="0" east="{length}" west="0"/>
  <road name="highway" length="{length}" id="1" junction="-1">
    <link/>
    <planView><geometry s="0" x="0" y="0" hdg="0" length="{length}"><line/></geometry></planView>
    <lanes>
      <laneSection s="0">
        <center><lane id="0" type="none" level="false"><roadMark sOffset="0" type="solid" weight="standard" color="standard" width="0.12"/></lane></center>
        <right>
{left}{right}        </right>
      </laneSection>
    </lanes>
  </road>
</OpenDRIVE>
"#,
        length = number(ROAD_LENGTH),
        left = lane(LEFT_LANE, "broken"),
        right = lane(RIGHT_LANE, "solid"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scene_is_written_with_its_numbers_and_escaped_words() {
        let scene = Scene {
            description: "R < 5 & \"fast\"".into(),
            vehicles: vec![PlacedVehicle {
                name: "Ego",
                lane: RIGHT_LANE,
                s: 100.0,
                speed: 20.5,
                length: 5.0,
            }],
            lane_change: None,
            max_time: 10.0,
            goal: Some(("Ego", 300.0)),
        };
        let xml = scene.to_xosc();
        assert!(xml.contains(r#"description="R &lt; 5 &amp; &quot;fast&quot;""#));
        assert!(xml.contains(r#"<LanePosition roadId="1" laneId="-2" offset="0" s="100"/>"#));
        assert!(xml.contains(r#"<AbsoluteTargetSpeed value="20.5"/>"#));
        assert!(xml.contains(r#"<SimulationTimeCondition value="10" rule="greaterThan"/>"#));
        assert!(xml.contains(r#"s="300"/></Position></ReachPositionCondition>"#));
        assert!(xml.contains(r#"<Center x="2.5" y="0" z="0.75"/>"#));
    }
}
