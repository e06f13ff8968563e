"""The paper's numbers: its KUKA Tables 1-3 as data, read from its LaTeX source
(``tests/test_tools.py`` compares them with it), and the readings of its goal sampling.

Values are the mean squared error over the joints (rad^2), ``mean(std)`` over 10 goals x 5 seeds x
5 policy initialisations: ``table[method][column value] = (mean, std)``.
"""

from __future__ import annotations

from dataclasses import dataclass

from warp_critic.running.goals import GOAL_NOISE  # noqa: F401  (the paper's two readings)

#: Method keys of the paper's tables: ours, and the two baselines (as ``warp_critic.methods`` names them).
PAPER_METHODS = ("ours", "ddpg", "meta-critic")

#: Table 1 (``table:gen_tasks_kuka``): new goals sampled at N(0, std) around the training goals.
PAPER_TABLE1: dict[str, dict[float, tuple[float, float]]] = {
    "ours": {
        0.1: (0.02, 0.02),
        0.2: (0.04, 0.03),
        0.3: (0.05, 0.04),
        0.4: (0.07, 0.05),
        0.5: (0.41, 0.58),
        0.6: (1.65, 2.63),
        0.7: (2.05, 3.78),
        0.8: (1.01, 1.92),
        0.9: (0.27, 0.2),
        1.0: (0.95, 0.8),
    },
    "ddpg": {
        0.1: (3.425, 2.136),
        0.2: (3.943, 2.415),
        0.3: (5.638, 1.621),
        0.4: (4.426, 2.841),
        0.5: (4.001, 1.735),
        0.6: (3.9, 1.664),
        0.7: (4.312, 2.268),
        0.8: (4.293, 1.609),
        0.9: (4.095, 2.85),
        1.0: (5.031, 3.801),
    },
    "meta-critic": {
        0.1: (4.149, 1.781),
        0.2: (3.817, 1.763),
        0.3: (4.962, 2.298),
        0.4: (4.413, 1.746),
        0.5: (5.611, 2.059),
        0.6: (5.544, 2.5),
        0.7: (4.622, 2.254),
        0.8: (4.77, 1.585),
        0.9: (4.754, 2.804),
        1.0: (7.771, 3.304),
    },
}

#: Table 2 (``table:gen_kuka_mass``): end-effector mass at meta-test ("training mass is at mass=3.12").
PAPER_TABLE2: dict[str, dict[float, tuple[float, float]]] = {
    "ours": {
        0.0: (0.066, 0.058),
        1.0: (0.061, 0.054),
        2.0: (0.06, 0.053),
        3.0: (0.06, 0.053),
        4.0: (0.06, 0.053),
        5.0: (0.06, 0.053),
        6.0: (0.06, 0.053),
        7.0: (0.06, 0.054),
        8.0: (0.061, 0.054),
        9.0: (0.061, 0.054),
    },
    "ddpg": {
        0.0: (3.688, 1.817),
        1.0: (4.276, 1.295),
        2.0: (5.132, 0.595),
        3.0: (3.494, 2.585),
        4.0: (2.141, 1.489),
        5.0: (1.882, 0.841),
        6.0: (4.503, 3.101),
        7.0: (3.919, 2.408),
        8.0: (3.96, 2.321),
        9.0: (2.327, 2.229),
    },
    "meta-critic": {
        0.0: (1.495, 0.105),
        1.0: (2.696, 0.865),
        2.0: (3.31, 1.198),
        3.0: (2.879, 0.621),
        4.0: (3.274, 0.409),
        5.0: (4.267, 1.215),
        6.0: (4.312, 0.375),
        7.0: (3.205, 1.314),
        8.0: (2.674, 0.912),
        9.0: (2.238, 0.704),
    },
}

#: Table 3 (``table:gen_kuka_link``): end-effector link length at meta-test ("training value is at length=0").
PAPER_TABLE3: dict[str, dict[float, tuple[float, float]]] = {
    "ours": {
        0.2: (0.009, 0.0),
        0.4: (0.009, 0.0),
        0.6: (0.009, 0.0),
        0.8: (0.009, 0.0),
        1.0: (0.021, 0.0),
        1.2: (0.021, 0.0),
        1.4: (0.021, 0.0),
        1.6: (0.021, 0.0),
        1.8: (0.021, 0.0),
        2.0: (0.021, 0.0),
    },
    "ddpg": {
        0.2: (3.717, 1.274),
        0.4: (5.295, 1.045),
        0.6: (4.341, 2.925),
        0.8: (5.197, 1.629),
        1.0: (1.644, 0.69),
        1.2: (1.926, 1.264),
        1.4: (3.39, 1.781),
        1.6: (1.616, 0.876),
        1.8: (3.628, 0.577),
        2.0: (2.918, 1.118),
    },
    "meta-critic": {
        0.2: (3.92, 0.661),
        0.4: (3.003, 0.461),
        0.6: (3.736, 1.101),
        0.8: (3.047, 0.409),
        1.0: (3.685, 0.95),
        1.2: (3.147, 1.079),
        1.4: (3.673, 1.961),
        1.6: (5.166, 0.627),
        1.8: (1.737, 0.032),
        2.0: (1.944, 0.561),
    },
}


@dataclass(frozen=True)
class PaperTable:
    """One of the paper's KUKA tables: ``values[method][column value] = (mean, std)``."""

    label: str  # the LaTeX label
    column: str  # the varied quantity, as the paper's column headers name it
    values: dict[str, dict[float, tuple[float, float]]]
    title: str  # what the report calls it


#: The paper's tables, by the names the report uses.
PAPER_TABLES: dict[str, PaperTable] = {
    "table1": PaperTable(
        "table:gen_tasks_kuka", "std", PAPER_TABLE1, "Table 1 (new goals, `table:gen_tasks_kuka`)"
    ),
    "table2": PaperTable(
        "table:gen_kuka_mass",
        "Mass",
        PAPER_TABLE2,
        "Table 2 (end-effector mass, `table:gen_kuka_mass`)",
    ),
    "table3": PaperTable(
        "table:gen_kuka_link",
        "length",
        PAPER_TABLE3,
        "Table 3 (end-effector link length, `table:gen_kuka_link`)",
    ),
}

#: Table 1's goal stds.
TABLE1_STDS: tuple[float, ...] = tuple(PAPER_TABLE1["ours"])
