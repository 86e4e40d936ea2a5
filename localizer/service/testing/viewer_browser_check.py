#!/usr/bin/python3
"""Loads the live viewer (docs/viewer.md) in headless Chromium through Selenium and checks the DOM.

Usage: viewer_browser_check.py URL SCREENSHOT.png EXPECTED_SESSIONS

Waits for the page to list EXPECTED_SESSIONS sessions with a tracker status, for every session's
pose to change (the event stream is live), for the map's points to be loaded, and for the time
surface of the first session to be shown after a click on its row; then saves a screenshot of the
window. Prints one JSON line of what it saw; exits 0 when every check passed, 1 otherwise (the
reason on stderr), 2 when Chromium or its driver cannot start.
"""
import json
import sys
import time

from selenium import webdriver
from selenium.common.exceptions import WebDriverException
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.by import By

STATUSES = {"TRACKING", "LOST", "RELOCALIZING", "INITIALIZING"}


def wait_for(what, condition, timeout_s=90.0):
    deadline = time.monotonic() + timeout_s
    last_error = None
    while time.monotonic() < deadline:
        try:
            value = condition()
            if value:
                return value
        except WebDriverException as error:  # the DOM changed under us: try again
            last_error = error
        time.sleep(0.1)
    raise AssertionError(f"timed out after {timeout_s} s waiting for {what}"
                         + (f" ({last_error})" if last_error else ""))


def sessions(driver):
    rows = driver.find_elements(By.CSS_SELECTOR, "#sessions tbody tr.session")
    return [{"id": row.get_attribute("data-id"),
             "status": row.find_element(By.CSS_SELECTOR, ".status").text,
             "pose": row.find_element(By.CSS_SELECTOR, ".pose").text,
             "poses": int(row.get_attribute("data-poses") or 0)} for row in rows]


def main():
    url, screenshot, expected = sys.argv[1], sys.argv[2], int(sys.argv[3])
    options = webdriver.ChromeOptions()
    options.binary_location = "/usr/bin/chromium"
    for argument in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                     "--window-size=1280,800", "--use-angle=swiftshader",
                     "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist"):
        options.add_argument(argument)
    try:
        driver = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)
    except WebDriverException as error:
        print(f"viewer_browser_check: cannot start Chromium: {error}", file=sys.stderr)
        return 2
    seen = {}
    try:
        driver.set_page_load_timeout(90)
        driver.get(url)
        wait_for("the page to load the map",
                 lambda: driver.find_element(By.TAG_NAME, "body").get_attribute("data-ready"))
        seen["points_drawn"] = int(driver.find_element(By.TAG_NAME, "body")
                                   .get_attribute("data-points-drawn"))
        if seen["points_drawn"] <= 0:
            raise AssertionError("the map's points were not loaded")
        first = wait_for(f"{expected} sessions with a status",
                         lambda: (lambda s: s if len(s) == expected and all(
                             x["status"] in STATUSES and x["pose"] for x in s) else None)(
                                 sessions(driver)))
        seen["first"] = first
        # Every session's pose changes: the event stream is live.
        before = {s["id"]: s["pose"] for s in first}
        later = wait_for("every session's pose to change",
                         lambda: (lambda s: s if len(s) == expected and all(
                             x["pose"] != before.get(x["id"]) for x in s) else None)(
                                 sessions(driver)))
        seen["later"] = later
        if not any(s["status"] == "TRACKING" for s in later):
            raise AssertionError(f"no session is TRACKING: {later}")
        # The time surface of the first session, on demand.
        driver.find_element(By.CSS_SELECTOR, "#sessions tbody tr.session").click()
        wait_for("the time surface picture",
                 lambda: int(driver.find_element(By.ID, "surface").get_attribute("data-loads")
                             or 0) >= 1)
        seen["surface_width"] = driver.execute_script(
            "return document.getElementById('surface').naturalWidth")
        seen["updates"] = int(driver.find_element(By.TAG_NAME, "body")
                              .get_attribute("data-session-updates"))
        seen["frames"] = int(driver.find_element(By.TAG_NAME, "body").get_attribute("data-frames"))
        time.sleep(0.5)  # a few more frames with the trails
        driver.save_screenshot(screenshot)
        print(json.dumps(seen))
        return 0
    except AssertionError as error:
        print(json.dumps(seen))
        print(f"viewer_browser_check: {error}", file=sys.stderr)
        try:
            driver.save_screenshot(screenshot)
        except WebDriverException:
            pass
        for entry in driver.get_log("browser"):
            print(f"browser console: {entry}", file=sys.stderr)
        return 1
    finally:
        driver.quit()


if __name__ == "__main__":
    sys.exit(main())
