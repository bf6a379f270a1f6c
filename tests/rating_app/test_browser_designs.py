"""A real browser (Debian chromium, headless) takes a rater through a pairwise and a parallel study against the app
served over HTTP, with the server's full viewing rule (MIN_VIEW 1): the answers it gave appear in the export.
The pairwise page is checked on a phone (A above B, played one after the other) and on a wide screen (side by
side). SAVE_SCREENSHOTS=1 writes docs/img/pairwise_page.png and docs/img/parallel_page.png
(SCREENSHOT_MANIFEST=path/manifest.csv to show real stimuli)."""

import os

import pytest
from helpers.design_pages import STATE_JS, play_page, rater_export, run_flow, screenshot, serve, shown_clips, trial_of
from helpers.fake_stimuli import write_fake_stimuli

from moglow_eval.core import study
from rating_app.store.manifest import load_manifest

pytestmark = pytest.mark.browser


@pytest.fixture(scope="module")
def design_stimuli(tmp_path_factory):
    return os.environ.get("SCREENSHOT_MANIFEST") or write_fake_stimuli(
        tmp_path_factory.mktemp("design_stimuli"), catch_nat=True
    )


@pytest.mark.parametrize("app_db_url", ["postgres"], indirect=True)
def test_pairwise_flow_in_a_real_browser(design_stimuli, app_db_url, browser):
    from selenium.webdriver.common.by import By

    levels = [2, 1, 0, -1, -2]
    layouts = []
    with serve(design_stimuli, app_db_url, "pairwise") as (app, url):

        def answer(s, wait):
            from selenium.webdriver.support import expected_conditions as EC

            index = int(s["count"].split()[0])
            layouts.append(("phone", s["a"], s["b"]))
            if index == 1:  # the same page on a wide screen: A and B side by side
                browser.set_window_size(1280, 900)
                wide = browser.execute_script(STATE_JS)
                layouts.append(("wide", wide["a"], wide["b"]))
            pref = levels[index % 5]
            btn = wait.until(EC.element_to_be_clickable((By.CSS_SELECTOR, f'button.pref[data-preference="{pref}"]')))
            if index == 1:
                screenshot(browser, "pairwise_page.png")
                browser.set_window_size(390, 844)
            btn.click()
            return trial_of(s["srcs"][0]), pref

        given, n_training, code = run_flow(browser, url, "pairwise", answer)
        rows, resp = rater_export(url, "pairwisepid")
        shown = shown_clips(app)
    assert code and n_training >= 1
    assert "pairs.csv" in resp.headers["Content-Disposition"]
    n_catch_pairs = sum(c.role == "catch" and c.condition == "BAD" for c in load_manifest(design_stimuli))
    assert len(given) == 3 + n_catch_pairs
    assert {(row["clip_a"], row["clip_b"]): int(row["preference"]) for row in rows} == {
        (shown[t]["A"], shown[t]["B"]): v for t, v in given.items()
    }
    assert sum(row["role"] == "catch" for row in rows) == n_catch_pairs
    # Every video fetched; failed_catch on every row exactly when the rater's random answers failed a catch pair.
    failed = any(
        study.pair_catch_failed(r["condition_a"], r["condition_b"], int(r["preference"]))
        for r in rows
        if r["role"] == "catch"
    )
    assert all(row["flags"] == ("failed_catch" if failed else "") and row["item"] for row in rows)
    phone = [(a, b) for kind, a, b in layouts if kind == "phone"]
    assert all(b[1] >= a[2] - 1 for a, b in phone), "on a phone B comes below A"
    wide = [(a, b) for kind, a, b in layouts if kind == "wide"]
    assert wide and all(abs(a[1] - b[1]) < 2 and b[0] > a[0] for a, b in wide), "side by side on a wide screen"
    errors = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert not errors, errors


@pytest.mark.parametrize("app_db_url", ["postgres"], indirect=True)
def test_parallel_flow_in_a_real_browser(design_stimuli, app_db_url, browser):
    from selenium.webdriver.common.by import By

    with serve(design_stimuli, app_db_url, "parallel") as (app, url):

        def answer(s, wait):
            from selenium.webdriver.support import expected_conditions as EC

            index = int(s["count"].split()[0])
            if index == 1:
                browser.set_window_size(1280, 900)
            play_page(browser, wait)
            sliders = browser.find_elements(By.CSS_SELECTOR, "#page-clips input[type=range]")
            values = {}
            for i, sl in enumerate(sliders):
                assert sl.is_enabled()
                v = (17 * (i + 1) + 7 * index) % 101
                browser.execute_script(
                    "arguments[0].value = arguments[1];arguments[0].dispatchEvent(new Event('input'));", sl, str(v)
                )
                values[sl.get_attribute("data-clip-id")] = v
            btn = wait.until(EC.element_to_be_clickable((By.ID, "page-submit")))
            if index == 1:
                screenshot(browser, "parallel_page.png")
                browser.set_window_size(390, 844)
            btn.click()
            return trial_of(s["srcs"][0]), values

        given, n_training, code = run_flow(browser, url, "parallel", answer)
        rows, resp = rater_export(url, "parallelpid")
    assert code and n_training >= 1
    n_catch_pages = len({c.item for c in load_manifest(design_stimuli) if c.role == "catch"})
    assert len(given) == 3 + n_catch_pages
    pages, catch = {}, {}
    for row in rows:
        pages.setdefault(row["page_id"], {})[row["clip_id"]] = int(row["rating"])
        if row["role"] == "catch":
            catch.setdefault(row["page_id"], {}).setdefault(row["condition"], []).append(int(row["rating"]))
        assert 0 <= int(row["rating"]) <= 100
    # Every video fetched; failed_catch on every row exactly when a catch page rated its BAD clip at or above NAT.
    failed = any(study.page_catch_failed(max(p[study.CATCH]), min(p[study.NATURAL])) for p in catch.values())
    assert all(row["flags"] == ("failed_catch" if failed else "") for row in rows)
    assert sorted(map(sorted, (p.items() for p in pages.values()))) == sorted(
        map(sorted, (v.items() for v in given.values()))
    )
    assert {p for p in pages} == {f"p{t}" for t in given}
    errors = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert not errors, errors
