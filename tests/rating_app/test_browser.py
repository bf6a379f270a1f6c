"""A real browser (Debian chromium, headless, phone-sized) takes a rater through the whole flow against the app
served over HTTP; the ratings it clicked appear in the export. SAVE_SCREENSHOTS=1 writes
docs/img/rating_page.png (SCREENSHOT_MANIFEST=path/manifest.csv to show real stimuli)."""

import pytest
from helpers.browser import acr_rater_flow

pytestmark = pytest.mark.browser


# The page does not depend on the database (the API suite covers both); one browser run keeps CI short.
@pytest.mark.parametrize("app_db_url", ["postgres"], indirect=True)
def test_rater_flow_in_a_real_browser(live_server, browser):
    acr_rater_flow(live_server, browser)
