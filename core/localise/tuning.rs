//! The particle filter's tuning ([`Settings`]): the match's `localiser` object and the
//! internal constants, which the filter and its likelihood field both read.

crate::settings! {
    /// Tuning of the filter (defaults as in AMCL where they apply); only `beams` is a
    /// match setting (the match's `localiser` object).
    #[derive(Debug, Clone, PartialEq)]
    pub struct Settings as "localiser" {
        /// Laser beams weighed per update, evenly spread over the scan; 0 localises from
        /// landmarks and odometry alone.
        pub beams: usize = 30, range(0, 181);
    }
    internal {
        pub min_particles: usize = 500;
        pub max_particles: usize = 2000;
        /// σ of the likelihood field's Gaussian (m): laser noise plus map-grid quantisation.
        pub sigma_hit: f32 = 0.1;
        pub z_hit: f32 = 0.9;
        pub z_rand: f32 = 0.1;
        /// Odometry motion noise: rotation from rotation, rotation from translation (rad per
        /// m), translation from translation, translation from rotation (m per rad). Std-dev
        /// form.
        pub alpha: [f32; 4] = Settings::alpha_for(&crate::sim::Physics::default());
        /// σ of a landmark's range (m) and bearing (rad) as the filter models them.
        pub landmark_range_sigma: f32 = 0.1;
        pub landmark_bearing_sigma: f32 = 4f32.to_radians();
        /// KLD-sampling: error bound ε, upper quantile z of the normal, bin size (m, rad).
        pub kld_err: f64 = 0.05;
        pub kld_z: f64 = 2.33;
        pub bin_xy: f32 = 0.2;
        pub bin_theta: f32 = 10f32.to_radians();
        /// Augmented MCL smoothing rates of the short- and long-term average likelihood.
        pub alpha_slow: f64 = 0.001;
        pub alpha_fast: f64 = 0.1;
        /// Inject only when the short-term likelihood has fallen below this fraction of the
        /// long-term one (1 = plain augmented MCL, injecting at any dip). Plain MCL lets one
        /// injected particle outscore the true cloud in the hallway when an opponent up close
        /// blocks most beams (a 1.2 m jump in one update); but 0.5 made the hallway without
        /// landmarks far worse (mean 0.8 m against 0.02 m), so it stays at 1 until tuned.
        pub inject_below: f64 = 1.0;
        /// Measurement updates happen once the robot has moved this far (m) or turned this
        /// much (rad) since the last one, or every `update_every` calls regardless. AMCL's
        /// defaults (0.2 m, π/6): the odometry between updates drifts by about a centimetre,
        /// and updating on every tick made the filter 70 % of a tick's cost.
        pub update_min_d: f32 = 0.2;
        pub update_min_a: f32 = std::f32::consts::FRAC_PI_6;
        pub update_every: u32 = 10;
        /// Spread of the initial cloud around the known start pose (m, rad).
        pub init_sigma_xy: f32 = 0.05;
        pub init_sigma_theta: f32 = 2f32.to_radians();
        /// Jitter added to resampled particles (m, rad) ("roughening"): without it a robot
        /// that stands still collapses onto copies of a few particles and can never move its
        /// belief.
        pub roughen_xy: f32 = 0.01;
        pub roughen_theta: f32 = 0.5f32.to_radians();
    }
}

impl Settings {
    /// The defaults, with a motion model for the robot's odometry noise in `physics`.
    pub fn for_odometry(physics: &crate::sim::Physics) -> Settings {
        Settings {
            alpha: Settings::alpha_for(physics),
            ..Settings::default()
        }
    }

    /// The motion model tuned for the default odometry noise (game-rules.md: about 5% of
    /// distance and 2° per metre), scaled with the noise in `p`. The tuned values inflate the
    /// sim's noise (1.5× per metre, 1.6× of distance, 2.5× of turns), as filters should: an
    /// over-confident motion model loses the robot. (The translation-from-rotation term has
    /// no counterpart in the sim; a little keeps turning on the spot from being certain.)
    fn alpha_for(p: &crate::sim::Physics) -> [f32; 4] {
        const TUNED: [f32; 4] = [0.05, 0.052_359_88, 0.08, 0.01]; // 0.052… = 3° in radians
        let d = crate::sim::Physics::default();
        // Ratios, so that the default noise gives the tuned values to the last bit.
        let scaled = |tuned: f32, v: f32, default: f32| tuned * (v / default);
        [
            scaled(TUNED[0], p.odometry.turn, d.odometry.turn),
            scaled(
                TUNED[1],
                p.odometry.heading_per_metre(),
                d.odometry.heading_per_metre(),
            ),
            scaled(TUNED[2], p.odometry.distance, d.odometry.distance),
            TUNED[3],
        ]
    }
}
