"""The datasets the course uses: files, sha256 hashes, sizes, public sources, citations,
and each run's EKF-SLAM defaults.

The values come from each dataset's provenance notes (summarised in the repository's
data/README.md). A file's default download URL is the raw GitHub URL of the exact commit it
was taken from,
``https://raw.githubusercontent.com/{repo}/{commit}/{path}``.

Adding a dataset: an entry here (files, citation, ``filter_defaults``) and its parser in
:mod:`annslam_lib.data.loaders`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field


@dataclass(frozen=True)
class DataFile:
    """One file of a dataset: name on disk, sha256 (hex), size (bytes), public URL."""

    name: str
    sha256: str
    size: int
    url: str


@dataclass(frozen=True)
class DatasetEntry:
    """A dataset: the files living in ``<data dir>/<folder>/`` and how to cite them."""

    name: str
    folder: str
    files: tuple[DataFile, ...]
    citation: str
    licence: str
    source: str
    optional: bool = False  # not fetched unless named (not used by the core chapters)
    #: SlamConfig fields that differ from its defaults on this run (``SlamConfig.for_dataset``)
    filter_defaults: dict = field(default_factory=dict)

    def file(self, filename: str) -> DataFile:
        for f in self.files:
            if f.name == filename:
                return f
        known = ", ".join(f.name for f in self.files)
        raise ValueError(f"dataset {self.name!r} has no file {filename!r}; its files are: {known}")


def _raw(repo: str, commit: str, path: str) -> str:
    return f"https://raw.githubusercontent.com/{repo}/{commit}/{path}"


_CP_REPO, _CP_COMMIT = "yuzehai1995/hwork_SLAM", "b4715234d795a5dd8155371e99b71f99803eb551"
_VP_REPO, _VP_COMMIT = "fernando10/Chameleon", "ef0bf6fc00bd14759e0a866e07ec965c470803b7"
_VPZ_REPO = "ezamorag/EKFSLAM_for_Victoria_Park_Benchmark"
_VPZ_COMMIT = "18bf9df527d996825b3646e3294f495c1381259a"
_MR_REPO, _MR_COMMIT = "ericguerrero/MUSI-lab-session-1", "bdd68804c10fd1016da19913a8036d1d74cc812a"

_GUIVANT_NEBOT = (
    "J. Guivant, E. Nebot, \"Optimization of the simultaneous localization and map-building "
    "algorithm for real-time implementation\", IEEE Transactions on Robotics and Automation, "
    "17(3):242-257, 2001."
)

# MRCLAM run 7, as in its SHA256SUMS (+ size in bytes); all under data/MRCLAM_Dataset7/.
_MRCLAM7 = """
4b4f4d9e65c452f58a6df2e02f25b5aced4300bd32cfbdb0acd8439692f09683      384 Barcodes.dat
eb401c2c97f8bcf827dd3c0695b4c8a71c495a217b0aa6f5465fe84bfda71345     1084 Landmark_Groundtruth.dat
bc03c2f7ff2735a013fd7e7538de3e3b015f216d1074dc5c27747efdf6409371  3212106 Robot1_Groundtruth.dat
83620487d6116c46d1695f7efa7bacf2c9998d700fe291a14cd34c090d082018   126109 Robot1_Measurement.dat
3f91fa6b20e11fe294b637e638569d8b593972f4ae86c434951638ad595a5e38  1933958 Robot1_Odometry.dat
776cbb8d88ce1c248a88f66bff3fff6ecbbecd898bb41e69b831d2afdaa207f8  3118635 Robot2_Groundtruth.dat
f6f3ba34a4f45d4cb31f5b325559e711a9dcc020dd15362a8e305ba22b1d3970   176419 Robot2_Measurement.dat
1076d5faf88c6478089cf58aa03704891681af00de90f040e7d209ac1905bc45  2011112 Robot2_Odometry.dat
3787a099121c2b145a2f117c319e14b239459d137d862b7dd3ebbed24ca829f0  2938233 Robot3_Groundtruth.dat
00c7bedd312294408d37be3173817deb40c59abe0e6be67b4ddaabf3e27c0f02   210778 Robot3_Measurement.dat
a174b6783e92e3021b9a9a633ba5fde6521414e9f8ac301f41db1b3ed53e9fb3  1818029 Robot3_Odometry.dat
05cd3680c40212a7d4fc8f47f555537da0504b100efeeea9383a1cf85543c069  3456054 Robot4_Groundtruth.dat
5e9f9f8e7b4f8fc760a9fae1bacffdef79f1fad0e3782d6296e85167fd9b4c3a    92920 Robot4_Measurement.dat
aac1385c268c3b6b6766c0b5afe2e4967529b66e38080d6fda37e265bb1b1008  2053055 Robot4_Odometry.dat
76d57915e69187b886272b2f9b8ec146e84ee48b13f1ac70ddd3ec21971d7089  3202672 Robot5_Groundtruth.dat
e0661e267a3b947f28e442735a45223bfdef6843d69944eedc6e295cd570366a   185857 Robot5_Measurement.dat
03f3fdb98aeed0c509480428a6313764b51cbb06c1cc4ce7dc1ea9a277e7fe1e  1973195 Robot5_Odometry.dat
"""

DATASETS: dict[str, DatasetEntry] = {
    "car_park": DatasetEntry(
        name="car_park",
        folder="acfr_car_park",
        files=(
            DataFile("data_set.mat", "f44c8adfa7e8e38ea6c40da3cd5d52bd8e029fc2d5ea27a9d7df24ad4ec98be7",
                     2324456, _raw(_CP_REPO, _CP_COMMIT, "hw4_slam/data_set.mat")),
            DataFile("beac_juan3.mat", "a6def97aef0e0f0d7a0a00f7014cdd1390fd8779ec7f17613c32b2e44aae1f36",
                     432, _raw(_CP_REPO, _CP_COMMIT, "hw4_slam/beac_juan3.mat")),
        ),
        citation="ACFR Car Park data set (J. Nieto, E. Nebot, J. Guivant; ACFR, University of "
                 "Sydney, 2002). " + _GUIVANT_NEBOT,
        licence="No licence statement found; ACFR research data: research use, cite ACFR.",
        source=f"github.com/{_CP_REPO} @ {_CP_COMMIT[:12]} (hw4_slam/), bytes unchanged",
        # the original ACFR program's noise values are SlamConfig's own defaults
        filter_defaults={},
    ),
    "victoria_park": DatasetEntry(
        name="victoria_park",
        folder="acfr_victoria_park",
        files=(
            DataFile("aa3_dr.mat", "6ce2c4f757023b7d275cc14f24ff2ffcca21ea68cfa360bc854e620a706eb358",
                     1239216, _raw(_VP_REPO, _VP_COMMIT, "data/victoria_park/aa3_dr.mat")),
            DataFile("aa3_gpsx.mat", "521fc4c6e0ea3851ffb463c3d9c0578044e9178c4fb87f37c703bb587f38c755",
                     89624, _raw(_VP_REPO, _VP_COMMIT, "data/victoria_park/aa3_gpsx.mat")),
            DataFile("VictoriaParkSinSincronizar.mat",
                     "8e5212b3028d40f64dcf7b43f68f89e67ea4b0c0b3ec01835997381fe9d96997",
                     1643042, _raw(_VPZ_REPO, _VPZ_COMMIT, "VictoriaParkSinSincronizar.mat")),
        ),
        citation=_GUIVANT_NEBOT + " Tree detections (VictoriaParkSinSincronizar.mat): W. Yu, "
                 "E. Zamora, A. Soria, \"Ellipsoid SLAM: a novel set membership method for "
                 "simultaneous localization and mapping\", Autonomous Robots, 40(1):125-137, 2016.",
        licence="aa3_*.mat: no licence statement found; ACFR research data, cite the paper. "
                "VictoriaParkSinSincronizar.mat: repository under the MIT License "
                "(c) 2016 ezamorag; the measurements are ACFR's.",
        source=f"github.com/{_VP_REPO} @ {_VP_COMMIT[:12]} (data/victoria_park/aa3_*.mat) and "
               f"github.com/{_VPZ_REPO} @ {_VPZ_COMMIT[:12]}; bytes unchanged",
        # trees are less precise than poles; GPS for the first 20 s with a gate (the
        # receiver jumps); tentative landmarks (a tree must be seen twice within 2 s)
        filter_defaults=dict(sigma_speed=0.7, sigma_steer=math.radians(7.0), sigma_range=0.5,
                             sigma_bearing=math.radians(2.0), min_range=1.0, max_range=30.0,
                             gate_prob=0.99, new_landmark_prob=0.99999,
                             landmark_min_observations=2, landmark_probation=2.0,
                             gps_mode="init", gps_init_seconds=20.0, gps_gate_prob=0.9999,
                             initial_sigma_xy=0.5, initial_sigma_phi=math.radians(3.0)),
    ),
    "mrclam7": DatasetEntry(
        name="mrclam7",
        folder="utias_mrclam_dataset7",
        files=tuple(
            DataFile(n, h, int(s), _raw(_MR_REPO, _MR_COMMIT, f"data/MRCLAM_Dataset7/{n}"))
            for h, s, n in (line.split() for line in _MRCLAM7.strip().splitlines())
        ),
        citation="K. Y. K. Leung, Y. Halpern, T. D. Barfoot, H. H. T. Liu, \"The UTIAS Multi-Robot "
                 "Cooperative Localization and Mapping Dataset\", International Journal of "
                 "Robotics Research, 30(8):969-974, 2011.",
        licence="No licence statement found; published by UTIAS for research use with citation.",
        source=f"github.com/{_MR_REPO} @ {_MR_COMMIT[:12]} (data/MRCLAM_Dataset7/), bytes unchanged",
        optional=True,
    ),
}


def core() -> list[str]:
    """Names of the datasets the course needs (fetched by default)."""
    return [name for name, entry in DATASETS.items() if not entry.optional]


def get(name: str) -> DatasetEntry:
    """The registry entry of dataset ``name``; ValueError listing the known names otherwise."""
    try:
        return DATASETS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown dataset {name!r}; known datasets: {', '.join(DATASETS)}") from None
