"""A study's sound check (CONTRACTS §5): the sample a session was given, and passing the check in a real browser
(play the sample, type the digits it speaks)."""


def sample_of(app, token):
    """The name of the sound-check sample the session `token` was given last (None before it fetched one)."""
    from sqlalchemy import select

    from rating_app.store.db import Rater, app_engine

    with app_engine(app).connect() as conn:
        return conn.execute(select(Rater.audio_sample).where(Rater.token == token)).scalar()


def pass_sound_check(driver, wait, app, screenshot=None):
    """Play the sound check's sample and type its digits, which the test reads from `app` (the rater would hear
    them). `screenshot`: a path to save the page to once the sample is fetched."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as EC

    wait.until(EC.visibility_of_element_located((By.ID, "audio-check")))
    wait.until(EC.element_to_be_clickable((By.ID, "audio-play"))).click()
    token = driver.execute_script("return sessionStorage.getItem('rating_app_session')")

    name = wait.until(lambda _: sample_of(app, token))  # the page fetched its sample
    if screenshot:
        driver.save_screenshot(str(screenshot))
    driver.find_element(By.ID, "audio-answer").send_keys(app.extensions["rating_app"]["audio_check"][name][1])
    wait.until(EC.element_to_be_clickable((By.ID, "audio-submit"))).click()
