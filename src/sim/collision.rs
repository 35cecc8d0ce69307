//! Capsule collision model of the robot, its tool and the cell (see poses.rs).
