"""Two ``ebm-eval --experiment`` processes ending at once each write the results document: the last one standing
holds every run either of them finished (``eval.paper.results_doc.report_lock``)."""

from __future__ import annotations

import multiprocessing
import time

from tests.paper.test_results_doc import cell, fake_run, parts_of


def publish(out: str, docs: str, records: str, delay: float) -> None:
    """What ``ebm-eval --experiment`` does once its runs are done, with a slow document (``delay`` seconds)."""
    import eval.paper.results_doc as results_doc
    import eval.paper.runner as runner
    from eval.executors import LocalExecutor

    render = results_doc.render_results

    def slow_render(*args, **kwargs):
        text = render(*args, **kwargs)
        time.sleep(delay)  # a writer that gathered the runs, then took its time: the race without a lock
        return text

    results_doc.render_results = slow_render
    settings = {"experiments": ["table1"], "out": out, "docs": docs, "records": records, "report_only": False}
    settings.update(scale="paper", seeds=None, device="cpu")
    runner.run_experiments(settings, [], LocalExecutor(), "ebm-eval --experiment table1", progress=False)


def test_two_writers_at_once_leave_a_document_with_both_their_runs(tmp_path):
    first, second = tmp_path / "first", tmp_path / "second"
    for seed, job in enumerate(cell(parts_of(first, "table1")["table1/particle/online"], "ebm").jobs):
        fake_run(job, -20.0 - seed, points=3)
    for seed, job in enumerate(cell(parts_of(second, "table1")["table1/particle/online"], "action-ff").jobs):
        fake_run(job, -800.0 - 10 * seed, points=3)
    docs, records = tmp_path / "docs" / "results.md", tmp_path / "records"
    context = multiprocessing.get_context("spawn")
    writers = [
        context.Process(target=publish, args=(str(first), str(docs), str(records), 3.0)),
        context.Process(target=publish, args=(str(second), str(docs), str(records), 0.0)),
    ]
    writers[0].start()
    time.sleep(1.0)  # the slow writer holds its document while the quick one starts and ends
    writers[1].start()
    for writer in writers:
        writer.join(timeout=240)
        assert writer.exitcode == 0
    text = docs.read_text()
    assert "| online | particle | EBM | -21.00 ± 0.82 | 3 |" in text
    assert "| online | particle | Action FF | -810.00 ± 8.16 | 3 |" in text
    assert not list(docs.parent.glob(".*.tmp"))  # the atomic writes left nothing behind
