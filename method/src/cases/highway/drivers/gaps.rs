//! Where the VUT stands against the two right-lane background vehicles:
//! its neighbours, safe gaps, overlaps, right-lane following and the
//! left lane's speed bounds.

use super::idm::IdmSteps;
use super::view::DriverView;
use crate::cases::highway::world::{Bv, ExitWorld};
use crate::cases::highway::zone::blocked;

/// The right-lane neighbours of a point `p`: the nearest BV at or ahead of
/// it and the nearest behind it. Of two BVs at the same position the slower
/// is the one ahead and the faster the one behind (the more constraining
/// either way), so nothing depends on the BVs' labels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Neighbours {
    /// The nearest BV at or ahead of the point, if any.
    pub ahead: Option<Bv>,
    /// The nearest BV behind the point, if any.
    pub behind: Option<Bv>,
}

/// The right-lane neighbours of `position` among `bvs` (see [`Neighbours`]).
pub fn neighbours(bvs: &[Bv; 2], position: f64) -> Neighbours {
    let (ahead, behind) = neighbour_indices(bvs, position);
    Neighbours {
        ahead: ahead.map(|i| bvs[i]),
        behind: behind.map(|i| bvs[i]),
    }
}

/// [`neighbours`] as indices into `bvs`: `(ahead, behind)`.
#[inline]
pub fn neighbour_indices(bvs: &[Bv; 2], position: f64) -> (Option<usize>, Option<usize>) {
    let (mut ahead, mut behind): (Option<usize>, Option<usize>) = (None, None);
    for (i, bv) in bvs.iter().enumerate() {
        if bv.position >= position {
            if ahead.is_none_or(|a| (bv.position, bv.speed) < (bvs[a].position, bvs[a].speed)) {
                ahead = Some(i);
            }
        } else if behind.is_none_or(|b| (bv.position, bv.speed) > (bvs[b].position, bvs[b].speed)) {
            behind = Some(i);
        }
    }
    (ahead, behind)
}

/// Whether a lane change at `position` keeps every BV at least its safe
/// time gap away, `|p − b| − ℓ ≥ t_min u`: the task's definition of a safe
/// lane change (the feasible zone's), which both controllers respect.
pub fn safe_gaps(world: &ExitWorld, bvs: &[Bv; 2], position: f64) -> bool {
    bvs.iter().all(|bv| {
        let (low, high) = blocked(world, bv.position, bv.speed);
        !(low < position && position < high)
    })
}

/// Whether a vehicle at `position` overlaps a BV (bumper gap < 0 either way).
pub fn overlaps(world: &ExitWorld, bvs: &[Bv; 2], position: f64) -> bool {
    bvs.iter()
        .any(|bv| (bv.position - position).abs() < world.length)
}

/// Right-lane car following: IDM behind the nearest BV ahead, within the
/// physical acceleration bounds.
pub fn follow_in_right_lane(idm: &IdmSteps, view: &DriverView) -> f64 {
    let ahead = neighbours(&view.traffic.bvs, view.position)
        .ahead
        .map(|bv| (bv.position - view.position - view.world.length, bv.speed));
    idm.accel(view.speed, ahead)
        .clamp(view.world.emergency_brake, view.world.accel.1)
}

/// `accel` cut so that the speed after one step stays in `[v_min, v_max]`:
/// both controllers keep to the lane-change boundary's speeds in the left
/// lane.
pub fn within_speed_bounds(world: &ExitWorld, speed: f64, accel: f64) -> f64 {
    accel.clamp(
        (world.speed.0 - speed) / world.dt,
        (world.speed.1 - speed) / world.dt,
    )
}
