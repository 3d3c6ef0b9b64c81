"""The typed reports read back from a motion's metadata (habitsim.bvh_mapping.ImportReport,
habitsim.stance.report.TransferRecord) and the pipeline's stage labels."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from habitsim.bvh_mapping import ImportReport
from habitsim.errors import HabitsimError, MetadataError
from habitsim.gaits import generate
from habitsim.pipeline import Stage, run_clip
from habitsim.stance.conform import conform
from habitsim.stance.labels import EditReason, StanceLabels, StanceSource
from habitsim.stance.report import ScheduleRecord, TransferRecord

IMPORT = {
    "contacts": {
        "method": "source foot path",
        "foot_joints": ["LF_Toe", "RF_Toe", "LH_Toe", "RH_Toe"],
        "foot_points": [["LF_Toe"], ["RF_Toe", "RF_Nub"], ["LH_Toe"], ["RH_Toe"]],
        "floors_m": [0.0, 0.001, 0.0, 0.002],
        "source_leg_length_m": 0.41,
        "duty": [0.6, 0.6, 0.62, 0.61],
    },
    "planted": {"max_reach_error_per_leg": 0.001, "min_toe_height_per_leg": 0.0},
    "contact_f1": [0.97, 0.95, 1.0, 0.9],
    "confidence": {"lf": 1.0, "rf": 0.9, "lh": 1.0, "rh": 1.0},
    "warnings": [],
}


def _dump(d: object) -> str:
    return json.dumps(d)  # key order included


def test_import_report_round_trip_and_typed_errors() -> None:
    rep = ImportReport.from_metadata({"import": IMPORT})
    assert rep is not None and rep.contacts.source is StanceSource.IMPORTED
    assert rep.contact_f1 == (0.97, 0.95, 1.0, 0.9) and rep.mean_contact_f1 == pytest.approx(0.955)
    assert _dump(rep.to_metadata()) == _dump(IMPORT)
    unplanted = {k: v for k, v in IMPORT.items() if k != "planted"}
    back = ImportReport.from_metadata({"import": unplanted})
    assert back is not None and back.planted is None and back.to_metadata() == unplanted
    assert ImportReport.from_metadata({}) is None and ImportReport.from_metadata(None) is None
    for field, broken in (
        ("import.contact_f1", {k: v for k, v in IMPORT.items() if k != "contact_f1"}),
        ("import.contact_f1", {**IMPORT, "contact_f1": "0.9"}),
        ("import.contacts.duty", {**IMPORT, "contacts": {**IMPORT["contacts"], "duty": None}}),
        ("import.confidence.rf", {**IMPORT, "confidence": {"rf": "high"}}),
        ("import", {"import": 3}["import"]),
    ):
        with pytest.raises(MetadataError, match=field.replace(".", r"\.")) as err:
            ImportReport.from_metadata({"import": broken})
        assert isinstance(err.value, HabitsimError)


@pytest.fixture(scope="module")
def conformed():
    src = generate("dog", "walk", seed=2, duration_s=2.0)
    out = generate("cat", "walk", seed=2, duration_s=2.0)
    return conform(out, src, {"method": "habit", "species": "cat"}, plant=True)


def test_transfer_record_round_trip_of_a_conformed_transfer(conformed) -> None:
    motion, report = conformed
    meta = motion.metadata
    rec = TransferRecord.from_metadata(meta)
    assert rec is not None and rec.contacts is not None
    assert rec.contacts.method == meta["transfer"]["contacts"]["method"]
    assert report.schedule == rec.contacts
    assert _dump(rec.to_metadata()) == _dump(meta["transfer"])
    assert rec.planted_how == ("no" if not report.planted.kept else report.planted.root)
    # the report's labels are the motion's, with their source and edits
    assert report.labels is not None
    np.testing.assert_array_equal(report.labels.array, motion.contacts)
    assert report.labels.source.value == rec.contacts.method or rec.contacts.method == "duty"


def test_transfer_record_of_other_methods_and_typed_errors() -> None:
    direct = {"transfer": {"method": "direct", "contacts": {"method": "source"}}}
    rec = TransferRecord.from_metadata(direct)
    assert rec is not None and rec.planted is None and rec.planted_how == "-"
    assert rec.to_metadata() == direct["transfer"]  # written back as read
    walking = {
        "method": "decoded",
        "source_f1": [1.0] * 4,
        "walking_stance": {
            "froude": 0.2,
            "walk_froude_max": 0.45,
            "duty_before": [0.4] * 4,
            "duty_after": [0.6] * 4,
        },
    }
    sched = ScheduleRecord.from_dict(walking)
    assert sched.walking_stance is not None and sched.walking_stance.froude == 0.2
    assert _dump(sched.to_dict()) == _dump(walking)
    carried = {"contacts": {"method": "decoded"}, "planted": {"kept": True, "root": "carried"}}
    assert TransferRecord.from_metadata({"transfer": carried}).planted_how == "carried"  # type: ignore[union-attr]
    assert TransferRecord.from_metadata({}) is None
    for field, broken in (
        ("transfer.contacts.method", {"contacts": {"source_f1": [1.0]}}),
        ("transfer.contacts.method", {"contacts": {"method": 3}}),
        ("transfer.contacts", {"contacts": "decoded"}),
        ("transfer.planted.kept", {"contacts": {"method": "decoded"}, "planted": {"root": "x"}}),
        (
            "transfer.contacts.walking_stance.duty_after",
            {
                "contacts": {
                    **walking,
                    "walking_stance": {**walking["walking_stance"], "duty_after": "x"},
                }
            },
        ),
    ):
        with pytest.raises(MetadataError, match=field.replace(".", r"\.")):
            TransferRecord.from_metadata({"transfer": copy.deepcopy(broken)})


def test_stage_contacts_method_from_its_labels() -> None:
    c = np.zeros((6, 4), dtype=bool)
    c[:3] = True
    for source, method in (
        (StanceSource.INPUT, "labels"),
        (StanceSource.DECODED, "decoded"),
        (StanceSource.SOURCE, "source"),
        (StanceSource.DETECTED, "detected"),
        (StanceSource.METHOD, "method"),
        (StanceSource.SIMULATED, "simulated"),
        (StanceSource.PLANNED, "planned"),
    ):
        st = Stage("transfer", None, StanceLabels(c, source))
        assert st.contacts_method == method and st.contacts is not None
    duty = StanceLabels(c, StanceSource.DETECTED).edited(~c, by="test", reason=EditReason.DUTY_FOOT)
    assert Stage("transfer", None, duty).contacts_method == "duty"
    assert Stage("track", None, None).contacts_method == "none"


def test_pipeline_stages_carry_labels_and_the_transfer_record() -> None:
    walk = generate("dog", "walk", seed=1, duration_s=1.5)
    run = run_clip(walk, "cat", method="direct", refine="none", track=False)
    assert run.source.labels is not None and run.source.labels.source is StanceSource.INPUT
    moved = run.transferred
    assert moved.labels is not None and moved.labels.source is StanceSource.SOURCE
    assert moved.contacts_method == "source" and moved.transfer is not None
    assert moved.transfer.contacts is not None and moved.transfer.contacts.method == "source"
    assert run.refined.labels is moved.labels and run.refined.transfer is moved.transfer
    assert run.tracked.labels is None and run.tracked.contacts_method == "none"
    assert all(isinstance(v, float | bool) for v in moved.metrics.values())
