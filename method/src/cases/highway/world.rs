//! The two-lane world of the highway-exit case (SPEC §5, paper Tables V–VI).
//!
//! Positions are front bumpers along the road (m); the vehicle under test
//! (VUT) starts in the left lane at `p = 0`, `v = 30 m/s` and must be in the
//! right lane when it reaches the off-ramp at `p = L`. Two background
//! vehicles (BVs) drive in the right lane. They are scripted, not reactive:
//! a BV keeps its speed unless it closes to within `d_cf` of the BV ahead,
//! then it takes that BV's speed. They do not see the VUT.

/// The world's constants. [`ExitWorld::paper`] holds the paper's values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExitWorld {
    /// Time step Δt (s).
    pub dt: f64,
    /// Off-ramp position L (m).
    pub exit: f64,
    /// The VUT's initial speed v₀ (m/s).
    pub start_speed: f64,
    /// Vehicle length ℓ (m): the bumper gap to a vehicle ahead at `b` is `b − p − ℓ`.
    pub length: f64,
    /// Car-following threshold d_cf between BVs (bumper gap, m).
    pub d_cf: f64,
    /// Safe time gap t_min of a lane change (s).
    pub t_min: f64,
    /// Speed bounds (v_min, v_max) of the lane-change boundary (m/s).
    pub speed: (f64, f64),
    /// Acceleration bounds (a_min, a_max) of the feasible zone and of the
    /// controllers' plans (m/s²).
    pub accel: (f64, f64),
    /// Time span of the feasible zone (s).
    pub horizon: f64,
    /// Hardest physical braking, used by car following in the right lane (m/s²).
    pub emergency_brake: f64,
    /// A run that has not reached the exit after this long failed (s).
    pub max_time: f64,
}

impl ExitWorld {
    /// The paper's settings: Δt 0.1 s, L 200 m, v₀ 30 m/s, d_cf 2 m,
    /// t_min 0.5 s, v ∈ [20, 40] m/s, a ∈ [−4, 2] m/s², t ∈ [0, 10] s. The
    /// vehicle length (5 m), emergency braking (−9 m/s²) and time cap (30 s)
    /// are ours.
    pub const fn paper() -> Self {
        Self {
            dt: 0.1,
            exit: 200.0,
            start_speed: 30.0,
            length: 5.0,
            d_cf: 2.0,
            t_min: 0.5,
            speed: (20.0, 40.0),
            accel: (-4.0, 2.0),
            horizon: 10.0,
            emergency_brake: -9.0,
            max_time: 30.0,
        }
    }

    /// Time steps in the zone's span: `t_k = k Δt`, `k = 0 … steps`.
    pub fn zone_steps(&self) -> usize {
        (self.horizon / self.dt).round() as usize
    }
}

/// A background vehicle's state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bv {
    /// Position along the road (m).
    pub position: f64,
    /// Speed (m/s), constant over the run.
    pub speed: f64,
}

/// The two BVs of a scenario `x = (p₁, v₁, p₂, v₂)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Traffic {
    /// The two BVs, as the scenario lists them.
    pub bvs: [Bv; 2],
}

impl Traffic {
    /// The traffic of scenario `x = (p₁, v₁, p₂, v₂)`.
    pub fn new(x: [f64; 4]) -> Self {
        Self {
            bvs: [
                Bv {
                    position: x[0],
                    speed: x[1],
                },
                Bv {
                    position: x[2],
                    speed: x[3],
                },
            ],
        }
    }

    /// `(front, rear)`: indices of the BV ahead and the one behind. At equal
    /// positions the slower counts as ahead, so nothing depends on which BV
    /// is called 1.
    pub fn order(&self) -> (usize, usize) {
        let [a, b] = self.bvs;
        if (b.position, -b.speed) > (a.position, -a.speed) {
            (1, 0)
        } else {
            (0, 1)
        }
    }

    /// The BV ahead (see [`Traffic::order`]).
    pub fn front(&self) -> Bv {
        self.bvs[self.order().0]
    }

    /// The BV behind (see [`Traffic::order`]).
    pub fn rear(&self) -> Bv {
        self.bvs[self.order().1]
    }

    /// One step: the rear BV, if it has closed to within `d_cf` of the front
    /// one and is faster, takes its speed; then both move at constant speed.
    pub fn step(&mut self, world: &ExitWorld) {
        let (front, rear) = self.order();
        let gap = self.bvs[front].position - self.bvs[rear].position - world.length;
        // The tolerance keeps the rule exact on the grid despite rounding
        // of positions accumulated in steps of 0.1 s.
        if gap <= world.d_cf + 1e-9 && self.bvs[rear].speed > self.bvs[front].speed {
            self.bvs[rear].speed = self.bvs[front].speed;
        }
        for bv in &mut self.bvs {
            bv.position += bv.speed * world.dt;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_faster_rear_bv_takes_the_front_speed_once_within_d_cf() {
        let world = ExitWorld::paper();
        // Rear BV at 30 m/s, 20 m (bumper 15 m) behind one at 25 m/s: the
        // gap closes at 5 m/s and reaches d_cf = 2 m after 2.6 s.
        let mut traffic = Traffic::new([20.0, 25.0, 0.0, 30.0]);
        let mut switched_at = None;
        for k in 1..=50 {
            traffic.step(&world);
            if switched_at.is_none() && traffic.bvs[1].speed == 25.0 {
                switched_at = Some(k);
            }
        }
        // The step that starts with gap ≤ 2 m: 15 − 5·0.1·k ≤ 2 ⇒ k = 26.
        assert_eq!(switched_at, Some(27));
        let gap = traffic.bvs[0].position - traffic.bvs[1].position - world.length;
        assert!((gap - 2.0).abs() < 1e-9, "gap {gap}");
        // A slower rear BV never changes speed.
        let mut apart = Traffic::new([20.0, 30.0, 0.0, 25.0]);
        for _ in 0..50 {
            apart.step(&world);
        }
        assert_eq!(apart.bvs[1].speed, 25.0);
    }
}
