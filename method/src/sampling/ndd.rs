//! The naturalistic baseline's distribution: the exposure itself.

use super::draw::Draw;
use crate::alias::AliasTable;
use crate::mass::GridMass;
use crate::test_stream::{test_rng, TestRng};
use rand::Rng;

/// The NDD baseline: `q = P`, every weight 1.
#[derive(Debug, Clone)]
pub struct NddDistribution {
    alias: AliasTable,
}

impl NddDistribution {
    /// Tests drawn from the exposure itself.
    pub fn new(exposure: &GridMass) -> Self {
        let alias = AliasTable::new(exposure.masses().to_vec())
            .expect("a mass function has positive total weight");
        Self { alias }
    }

    /// Test `index` of the campaign seeded `seed`: a cell drawn from `P`, weight 1.
    pub fn draw(&self, seed: u64, index: u64) -> Draw {
        self.draw_from(&mut test_rng(seed, index))
    }

    /// [`Self::draw`] from the test's stream `rng`.
    pub fn draw_from(&self, rng: &mut TestRng) -> Draw {
        Draw {
            cell: self.sample(rng),
            weight: 1.0,
        }
    }

    /// A cell drawn from `P` with `rng`.
    pub fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> usize {
        self.alias.sample(rng)
    }
}
