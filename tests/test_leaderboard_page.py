"""The leaderboard page: self-contained, sortable in a real browser, every link resolves."""

from __future__ import annotations

import functools
import http.server
import os
import shutil
import threading
import urllib.request
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fuelhm_bench.benchmark.page import leaderboard_html, write_leaderboard_page

CHROMIUM = os.environ.get("FUELHM_CHROMIUM", "/usr/bin/chromium")
CHROMEDRIVER = os.environ.get("FUELHM_CHROMEDRIVER", "/usr/bin/chromedriver")


def _results(root: Path) -> pd.DataFrame:
    rng = np.random.default_rng(0)
    rows = []
    for sc in ("paper_2012", "all_modes", "incipient"):
        for m, base in (("baselines.a:Good", 60), ("baselines.b:Fair", 30), ("baselines.c:Null", 0),
                        ("baselines.d:Broken", None)):
            entry = {"scenario": sc, "seed": 1, "method": m, "params": "a=2.0" if "Good" in m else "",
                     "status": "ok" if base is not None else "error",
                     "message": "" if base is not None else "ValueError: boom in fit\nTraceback ..."}
            if base is not None:
                v = base + rng.normal(0, 3)
                entry.update(summary_score=v, summary_score_ci_low=v - 5, summary_score_ci_high=v + 5,
                             fcr=rng.random(), brier=rng.random())
                d = root / f"{sc}-seed1" / m.replace(":", "_")
                d.mkdir(parents=True, exist_ok=True)
                (d / "table_v_detection.md").write_text("| a |\n")
                (d / "reliability.png").write_bytes(b"\x89PNG\r\n")
                entry["links"] = {"detection": f"{sc}-seed1/{m.replace(':', '_')}/table_v_detection.md",
                                  "reliability": f"{sc}-seed1/{m.replace(':', '_')}/reliability.png",
                                  "missing": f"{sc}-seed1/nothing.png"}
            rows.append(entry)
    return pd.DataFrame(rows)


def test_page_is_self_contained(tmp_path):
    page = leaderboard_html(_results(tmp_path), out_dir=tmp_path)
    assert "<script src" not in page and "<link" not in page and "@import" not in page
    stripped = page.replace('xmlns="http://www.w3.org/2000/svg"', "")
    assert "http://" not in stripped and "https://" not in stripped
    assert page.count('class="cd-method"') == 3  # the failed method is not ranked
    assert "Friedman test over 3 blocks and 3 methods" in page
    assert "boom in fit" in page and "Traceback" not in page  # first line of the message only
    assert "nothing.png" not in page  # links to missing files are dropped
    assert "[" in page and 'class="ci"' in page


def test_page_with_one_method_and_no_scores(tmp_path):
    one = _results(tmp_path)
    one = one[one["method"] == "baselines.d:Broken"]
    page = leaderboard_html(one, out_dir=tmp_path)
    assert "Fewer than two methods" in page and "Failed entries (3)" in page


def _serve(root: Path):
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(root))
    handler.log_message = lambda *a, **k: None
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server


def _driver(tmp_path):
    if not (Path(CHROMIUM).exists() and Path(CHROMEDRIVER).exists()):
        pytest.skip(f"no browser: {CHROMIUM} or {CHROMEDRIVER} missing "
                    f"(apt-get install -y chromium chromium-driver)")
    webdriver = pytest.importorskip("selenium.webdriver",
                                    reason="selenium missing (pip install '.[test]')")
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--disable-dev-shm-usage", f"--user-data-dir={tmp_path / 'chrome-profile'}"):
        options.add_argument(flag)
    return webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)


def test_sort_by_clicking_and_links_resolve_in_chromium(tmp_path):
    root = tmp_path / "site"
    results = _results(root)
    write_leaderboard_page(results, root)
    driver = _driver(tmp_path)
    server = _serve(root)
    try:
        from selenium.webdriver.common.by import By

        base = f"http://127.0.0.1:{server.server_address[1]}/"
        driver.get(base + "index.html")
        table = driver.find_element(By.ID, "scenario-all_modes")
        headers = [h.text.strip() for h in table.find_elements(By.CSS_SELECTOR, "thead th")]
        col = headers.index("summary_score")
        method_col = headers.index("method")

        def column(j):
            return [r.find_elements(By.TAG_NAME, "td")[j].get_attribute("data-sort")
                    for r in table.find_elements(By.CSS_SELECTOR, "tbody tr")]

        th = table.find_elements(By.CSS_SELECTOR, "thead th")[col]
        th.click()  # ascending, empty (failed) last
        asc = column(col)
        values = [float(v) for v in asc if v]
        assert values == sorted(values) and asc[-1] == ""
        th.click()  # descending
        desc = [float(v) for v in column(col) if v]
        assert desc == sorted(values, reverse=True)
        expected = results[results["scenario"] == "all_modes"].sort_values(
            "summary_score", ascending=False, na_position="last")["method"].tolist()
        assert column(method_col) == expected
        table.find_elements(By.CSS_SELECTOR, "thead th")[method_col].click()
        assert column(method_col) == sorted(expected, key=str.lower)
        hrefs = {a.get_attribute("href") for a in driver.find_elements(By.TAG_NAME, "a")}
        assert len(hrefs) == 18  # 3 scenarios x 3 methods x 2 existing files
        for href in hrefs:
            with urllib.request.urlopen(href, timeout=10) as resp:
                assert resp.status == 200, href
        assert driver.find_element(By.ID, "cd-diagram").find_elements(By.TAG_NAME, "svg")
    finally:
        driver.quit()
        server.shutdown()
    shutil.rmtree(tmp_path / "chrome-profile", ignore_errors=True)
