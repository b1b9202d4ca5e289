"""The real-to-sim force pipeline: an actuated MANO hand in MuJoCo tracks a demonstration and
the contact forces that move the object are read out (see DESIGN.md, "Physics conventions")."""
