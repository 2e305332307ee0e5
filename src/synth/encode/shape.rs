//! Which simulated point goes where in a written cloud: the slots of the
//! `/lidar/points` layout, shared by `/truth/points`.

use crate::synth::scene::{CloudLayout, LaserOrder};
use crate::synth::sensor::{SimPoint, SimScan, World};

/// One point of a written cloud: a return, or a pixel without one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Slot {
    /// Index into the scan's points.
    Return(u32),
    /// No return from this beam and column (dense layouts only).
    Empty { ring: u16, column: u32 },
}

/// Which point goes where in a written cloud (and in its `/truth/points`).
#[derive(Debug, Clone)]
pub struct CloudShape {
    pub height: u32,
    pub width: u32,
    /// Row by row.
    pub slots: Vec<Slot>,
}

impl CloudShape {
    pub fn new(world: &World, scan: &SimScan) -> Self {
        let beams = world.lasers.len();
        let columns = world.scenario.lidar.columns as usize;
        let returns = || (0..scan.points.len() as u32).map(Slot::Return);
        let unorganized = |slots: Vec<Slot>| Self {
            height: 1,
            width: slots.len() as u32,
            slots,
        };
        // A beams x columns grid, the pixel of (ring, column) at `at(ring, column)`.
        let grid = |at: &dyn Fn(usize, usize) -> usize| {
            let mut slots = vec![Slot::Return(0); beams * columns];
            for ring in 0..beams {
                for column in 0..columns {
                    slots[at(ring, column)] = Slot::Empty {
                        ring: ring as u16,
                        column: column as u32,
                    };
                }
            }
            for (i, p) in scan.points.iter().enumerate() {
                slots[at(usize::from(p.ring), p.column as usize)] = Slot::Return(i as u32);
            }
            slots
        };
        match world.scenario.lidar.layout {
            CloudLayout::RingTime
            | CloudLayout::RingField(_)
            | CloudLayout::FiringOrder { sparse: true } => unorganized(returns().collect()),
            CloudLayout::LaserOrder(order) => {
                let mut slots: Vec<Slot> = returns().collect();
                let key = |slot: &Slot| {
                    let Slot::Return(i) = *slot else {
                        return (0, 0);
                    };
                    let p = &scan.points[i as usize];
                    match order {
                        // Points are in firing order already: a stable sort by ring.
                        LaserOrder::LowestFirst => (usize::from(p.ring), 0),
                        // Top laser first; counter-clockwise from straight
                        // ahead (column columns/2) is decreasing column.
                        LaserOrder::Kitti => (
                            beams - 1 - usize::from(p.ring),
                            (columns + columns / 2 - p.column as usize) % columns,
                        ),
                    }
                };
                slots.sort_by_key(key);
                unorganized(slots)
            }
            CloudLayout::Organized => Self {
                height: beams as u32,
                width: columns as u32,
                slots: grid(&|ring, column| (beams - 1 - ring) * columns + column),
            },
            CloudLayout::FiringOrder { sparse: false } => {
                unorganized(grid(&|ring, column| column * beams + ring))
            }
        }
    }

    pub(super) fn point<'s>(&self, scan: &'s SimScan, slot: Slot) -> Option<&'s SimPoint> {
        match slot {
            Slot::Return(i) => scan.points.get(i as usize),
            Slot::Empty { .. } => None,
        }
    }

    pub(super) fn dense(&self) -> bool {
        self.slots.iter().all(|s| matches!(s, Slot::Return(_)))
    }
}
