//! The command line's names for the library's choices. The library's enums
//! know nothing of clap; each is mirrored here with the `--help` text of its
//! values and converted in [`super::resolve`].

/// A clap value enum mirroring a library enum variant for variant.
macro_rules! choice {
    ($(#[$meta:meta])* $name:ident => $library:path { $($(#[$vmeta:meta])* $variant:ident),+ $(,)? }) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
        pub(crate) enum $name {
            $($(#[$vmeta])* $variant),+
        }

        impl From<$name> for $library {
            fn from(choice: $name) -> Self {
                match choice {
                    $($name::$variant => <$library>::$variant),+
                }
            }
        }
    };
}

choice!(
    /// What a pixel shows.
    RenderChannel => looming::commands::render::RenderChannel {
        /// Fused looming of the cell, grey where masked.
        Fused,
        /// LiDAR-only looming of the cell wherever computed, masked cells
        /// included (the paper's LiDAR-only figure, edge effects and all).
        Lidar,
        /// `L_ego` of the cell's point (the paper's LiDAR + IMU figure); grey
        /// without a velocity.
        Ego,
        /// `D = L_lidar - L_ray_ego`, grey where masked.
        Disagreement,
        /// Threat level of the cell, grey where masked.
        Threat,
    }
);

choice!(
    /// How the scan is drawn.
    RenderView => looming::commands::render::RenderView {
        /// The range image: a row of cells per beam (highest at the top), forward
        /// at the centre column, the vehicle's left on the image's left.
        Range,
        /// The cloud seen from above: x (forward) up, y (left) left, the sensor at
        /// the centre.
        Top,
    }
);

choice!(
    /// Which per-point fields `/looming/points` carries.
    FieldSet => looming::annotate::FieldSet {
        /// x, y, z, the fused looming and its colour.
        Default,
        /// Also L_lidar, L_ego, L_ray_ego, D, confidence, threat level and mask.
        Full,
    }
);

choice!(
    /// Chunk compression of the output.
    OutputCompression => looming::output::OutputCompression { Zstd, Lz4, None }
);

choice!(
    /// Which way a spinning LiDAR turns, seen from above; its sweep starts behind.
    SweepDirection => looming::kitti::SweepDirection {
        /// Measured on KITTI's HDL-64E (docs/kitti.md): timing points this way
        /// removes the motion seam behind the car.
        CounterClockwise,
        /// The other way (`looming synth`'s sensor, many Velodyne drivers).
        Clockwise,
    }
);

choice!(
    /// What `process` does with a log without a LiDAR topic.
    NoLidarPolicy => looming::pipeline::NoLidarPolicy {
        /// Refuse it (exit 2), listing its channels.
        Refuse,
        /// Copy every record through, with the run record and no looming
        /// channel.
        Copy,
    }
);
