"""Passing a study's sound check in a real browser (CONTRACTS §5): play the sample, type the digits it speaks."""


def pass_sound_check(driver, wait, app, screenshot=None):
    """Play the sound check's sample and type its digits, which the test reads from `app` (the rater would hear
    them). `screenshot`: a path to save the page to once the sample is fetched."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as EC
    from sqlalchemy import select

    from rating_app.store.db import Rater, app_engine

    wait.until(EC.visibility_of_element_located((By.ID, "audio-check")))
    wait.until(EC.element_to_be_clickable((By.ID, "audio-play"))).click()
    token = driver.execute_script("return sessionStorage.getItem('rating_app_session')")

    def sample(_):
        with app_engine(app).connect() as conn:
            return conn.execute(select(Rater.audio_sample).where(Rater.token == token)).scalar()

    name = wait.until(sample)  # the page fetched its sample
    if screenshot:
        driver.save_screenshot(str(screenshot))
    driver.find_element(By.ID, "audio-answer").send_keys(app.extensions["rating_app"]["audio_check"][name][1])
    wait.until(EC.element_to_be_clickable((By.ID, "audio-submit"))).click()
