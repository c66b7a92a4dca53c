"""The paper's figures that the reports set beside srlab's."""

# The paper's Table II and the non-zero cells of its Table III (reliability of LTM after
# 50 episodic trials), keyed by our stimulus and behaviour names.
PAPER_TABLE_II = {"simulation": (5, 250), "robot": (2, 100)}
PAPER_TABLE_III: dict[str, dict[str, dict[str, float]]] = {
    "Obstacle_M_M": {
        "rightturn15": {"dp": 1.0, "rp": 0.13, "kp": 0.27},
        "leftturn30": {"rp": 0.12},
    },
    "Obstacle_M_R": {
        "goforward1": {"rp": 0.13},
        "goforward2": {"rp": 0.17},
        "goforward3": {"dp": 1.0, "rp": 0.19, "kp": 0.73},
        "goforward4": {"rp": 0.33},
        "goforward5": {"rp": 0.13},
    },
    "Obstacle_R_L": {
        "leftturn45": {"dp": 0.08, "rp": 0.1},
        "leftturn30": {"dp": 0.29, "rp": 0.42, "kp": 0.67},
    },
    "Obstacle_R_M": {
        "leftturn45": {"dp": 0.12, "rp": 0.14},
        "leftturn30": {"dp": 0.17, "rp": 0.36, "kp": 0.48},
    },
    "Obstacle_R_R": {"leftturn30": {"dp": 0.04, "rp": 0.23, "kp": 0.33}},
}
