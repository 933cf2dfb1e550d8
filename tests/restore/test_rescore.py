"""restore.studies.rescore: its section replaces the last one, or goes before the held-out section once."""
from restore.studies.budgets import shipped
from restore.studies.rescore import RESCORE_BEGIN, RESCORE_END, shipped_models, write_into


def test_section_is_inserted_once_then_replaced(tmp_path):
    doc = tmp_path / "RESULTS.md"
    doc.write_text("# R\n\n## Pipeline comparison\n\nold\n\n## Held-out photographs\n\nheld\n")
    write_into(doc, f"{RESCORE_BEGIN}\n## Re-scored\n\nfirst\n{RESCORE_END}")
    text = doc.read_text()
    assert text.index("first") < text.index("## Held-out photographs") and "old" in text and "held" in text
    write_into(doc, f"{RESCORE_BEGIN}\n## Re-scored\n\nsecond\n{RESCORE_END}")
    text = doc.read_text()
    assert "second" in text and "first" not in text and text.count(RESCORE_BEGIN) == 1
    assert text.endswith("held\n")


def test_the_shipped_weights_are_found():
    models = shipped_models()
    assert {row for row, _ in models} == set(shipped()["rows"]) and len(models) == 2 * len(shipped()["rows"])
    assert all(p.name == "model.pt" and p.is_file() for p in models.values())


def test_the_time_spent_sums_items_and_rows_over_resumes(tmp_path):
    import json

    from restore.studies.rescore import spent_seconds
    (tmp_path / "timing.jsonl").write_text("".join(json.dumps({"item": i, "seconds": s}) + "\n"
                                                   for i, s in ((1, 60.0), (2, 30.0))))
    (tmp_path / "row_seconds.json").write_text(json.dumps({"input": 10.0, "dep": 20.0}))
    assert spent_seconds(tmp_path, tmp_path) == 120.0
