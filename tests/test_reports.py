"""The typed reports read back from a motion's metadata (habitsim.bvh_mapping.ImportReport,
habitsim.stance.report.TransferRecord), a refinement report's contacts.cleaning
(habitsim.refine.cleaning.CleaningRecord) and the pipeline's stage labels."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from habitsim.bvh_mapping import ImportReport
from habitsim.errors import HabitsimError, MetadataError
from habitsim.gaits import generate
from habitsim.pipeline import Stage, run_clip
from habitsim.refine.cleaning import CleaningRecord, clean_contact_labels, cleaning_summary
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


RETRIEVAL = {
    "neighbour": "lion",
    "text_distance": 0.1234,
    "morphology_distance": 0.0456,
    "explanation": "tiger: habits of lion (nearest by description)",
}


def test_transfer_record_reads_retrieval_levelled_and_habit_species() -> None:
    held_out = {
        "habit_species": "lion",
        "levelled": {"pitch_deg": -3.5, "fore_minus_hind_per_leg": -0.0412},
        "method": "habit",
        "retrieval": RETRIEVAL,
        "contacts": {
            "method": "duty",
            "gait": "walk",
            "duty_factor": 0.6,
            "feet_by_duty": ["LF", "RF"],
        },
        "planted": False,
    }
    rec = TransferRecord.from_metadata({"transfer": held_out})
    assert rec is not None and rec.retrieval is not None and rec.levelled is not None
    assert (
        rec.retrieval.neighbour == "lion" and rec.retrieval.explanation == RETRIEVAL["explanation"]
    )
    assert rec.levelled.pitch_deg == -3.5 and rec.levelled.fore_minus_hind_per_leg == -0.0412
    assert rec.habit_species == "lion"
    assert rec.contacts is not None and rec.contacts.detail("feet_by_duty") == ["LF", "RF"]
    assert _dump(rec.to_metadata()) == _dump(held_out)  # byte-identical, key order too
    # a training target: retrieval written None and read back as written
    trained = {**held_out, "habit_species": "cat", "retrieval": None}
    del trained["levelled"]
    rec = TransferRecord.from_metadata({"transfer": trained})
    assert rec is not None and rec.retrieval is None and rec.levelled is None
    assert _dump(rec.to_metadata()) == _dump(trained)
    with pytest.raises(MetadataError, match=r"transfer\.contacts\.gait"):
        TransferRecord.from_metadata(
            {"transfer": {"contacts": {"method": "duty"}}}
        ).contacts.detail(  # type: ignore[union-attr]
            "gait"
        )
    for field, broken in (
        ("transfer.retrieval.explanation", {"retrieval": {**RETRIEVAL, "explanation": 3}}),
        ("transfer.retrieval.neighbour", {"retrieval": {"explanation": "x"}}),
        ("transfer.retrieval", {"retrieval": "lion"}),
        ("transfer.levelled.pitch_deg", {"levelled": {"fore_minus_hind_per_leg": 0.1}}),
        (
            "transfer.levelled.fore_minus_hind_per_leg",
            {"levelled": {"pitch_deg": 1.0, "fore_minus_hind_per_leg": "up"}},
        ),
        ("transfer.habit_species", {"habit_species": 7}),
    ):
        with pytest.raises(MetadataError, match=field.replace(".", r"\.")):
            TransferRecord.from_metadata({"transfer": copy.deepcopy(broken)})


CLEANING = {
    "frames_changed": 3,
    "LF": {"trimmed": 1, "filled": 1, "dropped": 0},
    "RF": {"trimmed": 0, "filled": 0, "dropped": 0},
    "LH": {"trimmed": 0, "filled": 0, "dropped": 1},
    "RH": {"trimmed": 0, "filled": 0, "dropped": 0},
}


def test_cleaning_record_round_trip_of_a_cleaning_summary() -> None:
    c = np.zeros((40, 4), dtype=bool)
    c[5:20] = True
    c[25:35] = True
    c[21, 0] = True  # a blip of one frame: LF changed
    c[12, 1] = False  # a gap of one frame: filled
    toes = np.zeros((40, 4, 3))
    labels = StanceLabels(c, StanceSource.GIVEN)
    cleaned = clean_contact_labels(labels, toes, fps=30.0, leg_length=0.3)
    summary = cleaning_summary(cleaned)
    rec = CleaningRecord.from_dict(summary)
    assert rec.frames_changed == summary["frames_changed"] > 0
    assert [k for k, _ in rec.feet] == ["LF", "RF", "LH", "RH"]
    assert _dump(rec.to_dict()) == _dump(summary)
    report = {"contacts": {"source": "given", "cleaning": summary}}
    assert CleaningRecord.from_report(report) == rec
    assert dict(rec.feet)["RF"].filled == 1 and dict(rec.feet)["LF"].changed
    assert all(f.to_dict() == summary[k] for k, f in rec.feet)
    assert not dict(rec.feet)["RH"].changed


def test_cleaning_record_absent_and_typed_errors() -> None:
    assert CleaningRecord.from_report({}) is None
    assert CleaningRecord.from_report({"contacts": {"cleaning": None}}) is None
    rec = CleaningRecord.from_report({"contacts": {"cleaning": CLEANING}})
    assert rec is not None and _dump(rec.to_dict()) == _dump(CLEANING)
    for field, broken in (
        (
            "contacts.cleaning.frames_changed",
            {k: v for k, v in CLEANING.items() if k != "frames_changed"},
        ),
        ("contacts.cleaning.frames_changed", {**CLEANING, "frames_changed": "3"}),
        ("contacts.cleaning.LF.trimmed", {**CLEANING, "LF": {"filled": 1, "dropped": 0}}),
        (
            "contacts.cleaning.LH.dropped",
            {**CLEANING, "LH": {"trimmed": 0, "filled": 0, "dropped": 1.5}},
        ),
        ("contacts.cleaning.RF", {**CLEANING, "RF": [0, 0, 0]}),
        ("contacts.cleaning", "none"),
    ):
        with pytest.raises(MetadataError, match=field.replace(".", r"\.")) as err:
            CleaningRecord.from_report({"contacts": {"cleaning": copy.deepcopy(broken)}})
        assert isinstance(err.value, HabitsimError)
    with pytest.raises(MetadataError, match="contacts"):
        CleaningRecord.from_report({"contacts": "cleaned"})
