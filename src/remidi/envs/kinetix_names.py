"""Kinetix's held-out level names per size, without importing Kinetix, so metrics and plots are
known before the extra is installed (tests/test_kinetix.py checks them against its files)."""

HELD_OUT = {
    "s": ("h0_weak_thrust", "h1_thrust_over_ball", "h2_one_wheel_car", "h3_point_the_thruster", "h4_thrust_aim",
          "h5_rotate_fall", "h6_unicycle_right", "h7_unicycle_left", "h8_unicycle_balance",
          "h9_explode_then_thrust_over"),
    "m": ("arm_hard", "arm_left", "arm_right", "arm_up", "h0_unicycle", "h1_car_left", "h2_car_right",
          "h3_car_thrust", "h4_thrust_the_needle", "h5_angry_birds", "h6_thrust_over", "h7_car_flip",
          "h8_weird_vehicle", "h9_spin_the_right_way", "h10_thrust_right_easy", "h11_thrust_left_easy",
          "h12_thrustfall_left", "h13_thrustfall_right", "h14_thrustblock", "h15_thrustshoot",
          "h16_thrustcontrol_right", "h17_thrustcontrol_left", "h18_thrust_right_very_easy",
          "h19_thrust_left_very_easy"),
    "l": ("car_launch", "car_swing_around", "chain_lander", "chain_thrust", "gears", "grasp_easy", "grasp_hard",
          "h0_angrybirds", "h1_car_left", "h2_car_ramp", "h3_car_right", "h4_cartpole", "h5_flappy_bird", "h6_lorry",
          "h7_maze_1", "h8_maze_2", "h9_morph_direction", "h10_morph_direction_2", "h11_obstacle_avoidance",
          "h12_platformer_1", "h13_platformer_2", "h14_simple_thruster", "h15_swing_up", "h16_thruster_goal",
          "h17_unicycle", "hard_beam_balance", "hard_cartpole_thrust", "hard_cartpole_wheels", "hard_lunar_lander",
          "hard_pinball", "lever_puzzle", "mjc_half_cheetah", "mjc_half_cheetah_easy", "mjc_hopper",
          "mjc_hopper_easy", "mjc_swimmer", "mjc_walker", "mjc_walker_easy", "pr", "rail"),
}
SIZES = ("s", "m", "l")


def natural_key(name: str) -> list:
    """Sort key putting ``h2`` before ``h10``."""
    import re

    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", name)]


def eval_set_names(size: str) -> tuple[str, ...]:
    """The evaluation sets of a task trained at ``size``: ``<level size>_<name>`` for the held-out
    levels of ``size`` and of every smaller size."""
    return tuple(f"{s}_{n}" for s in SIZES[:SIZES.index(size) + 1] for n in HELD_OUT[s])
