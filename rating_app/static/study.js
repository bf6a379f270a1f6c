// The rater's page: consent -> familiarisation -> rating trials -> completion, all through the JSON API.
// No build step; plain browser JavaScript.
(function () {
  "use strict";
  var $ = function (id) { return document.getElementById(id); };
  var app = $("app");
  var KEY = "rating_app_session";
  var token = null;
  var trial = null;          // the trial on screen
  var lastPhase = null;
  var watchedMs = 0, playStart = null, answered = false;
  var video = $("video");
  var rateButtons = Array.prototype.slice.call(document.querySelectorAll("button.rate"));

  function show(id) {
    ["welcome", "intro", "trial", "rating-intro", "done", "full", "error"].forEach(function (s) {
      $(s).hidden = (s !== id);
    });
    window.scrollTo(0, 0);
  }

  function fail(msg) {
    $("error-msg").textContent = msg;
    show("error");
  }

  // fetch JSON with a few retries on network errors and 5xx (a blip must not lose the rater).
  function api(method, path, body, tries) {
    tries = tries === undefined ? 5 : tries;
    var opts = { method: method, headers: { "Accept": "application/json" } };
    if (body !== undefined) {
      opts.headers["Content-Type"] = "application/json";
      opts.body = JSON.stringify(body);
    }
    return fetch(path, opts).then(function (r) {
      if (r.status >= 500 && tries > 1) { throw new Error("server " + r.status); }
      return r.json().catch(function () { return {}; }).then(function (data) {
        return { status: r.status, data: data };
      });
    }).catch(function (err) {
      if (tries > 1) {
        return new Promise(function (res) { setTimeout(res, 700 * (6 - tries)); })
          .then(function () { return api(method, path, body, tries - 1); });
      }
      throw err;
    });
  }

  function logEvent(kind, detail) {
    if (!token) { return; }
    api("POST", "/api/sessions/" + token + "/events",
        { kind: kind, detail: String(detail).slice(0, 500), trial_id: trial ? trial.trial_id : null }, 2)
      .catch(function () {});
  }

  function start() {
    $("start").disabled = true;
    var body = {};
    ["external_id", "study_id", "session_id"].forEach(function (k) {
      var v = app.dataset[k.replace(/_([a-z])/g, function (_, c) { return c.toUpperCase(); })];
      if (v) { body[k] = v; }
    });
    api("POST", "/api/sessions", body).then(function (r) {
      if (r.status === 409 && r.data.full) {
        $("full-msg").textContent = r.data.error;
        show("full");
        return;
      }
      if (r.status !== 201 && r.status !== 200) { fail(r.data.error || "could not start (" + r.status + ")"); return; }
      token = r.data.session;
      try { sessionStorage.setItem(KEY, token); } catch (e) { /* private mode: no resume */ }
      $("n-training").textContent = r.data.n_training;
      next();
    }).catch(function () { fail("The server cannot be reached. Please check your connection."); });
  }

  function next() {
    api("GET", "/api/sessions/" + token + "/next").then(function (r) {
      if (r.status === 404 || r.status === 410) {
        try { sessionStorage.removeItem(KEY); } catch (e) {}
        fail(r.status === 410 ? r.data.error : "This session is unknown. Please reload the page to start again.");
        return;
      }
      if (r.status === 409 && r.data.full) {
        try { sessionStorage.removeItem(KEY); } catch (e) {}
        $("full-msg").textContent = r.data.error;
        show("full");
        return;
      }
      if (r.status !== 200) { fail(r.data.error || "unexpected answer " + r.status); return; }
      if (r.data.done) { finish(r.data); return; }
      trial = r.data.trial;
      if (trial.phase === "training" && trial.index === 1 && lastPhase === null) {
        lastPhase = "intro";
        show("intro");
        return;
      }
      if (trial.phase === "rating" && trial.index === 1 && lastPhase !== "rating") {
        lastPhase = "rating";
        show("rating-intro");
        return;
      }
      present();
    }).catch(function () { fail("The server cannot be reached. Please check your connection."); });
  }

  function present() {
    lastPhase = trial.phase;
    answered = false;
    watchedMs = 0;
    playStart = null;
    var training = trial.phase === "training";
    $("phase-label").textContent = training ? "Example" : "Video";
    $("trial-count").textContent = trial.index + " of " + trial.of;
    $("question").textContent = training ? "Just watch this example." : "How natural does this motion look?";
    $("buttons").classList.toggle("training", training);
    $("continue").hidden = !training;
    $("continue").disabled = true;
    $("replay").disabled = true;
    $("video-msg").hidden = true;
    rateButtons.forEach(function (b) { b.disabled = true; });
    show("trial");
    video.src = trial.video_url;
    video.load();
    var p = video.play();
    if (p && p.catch) {
      p.catch(function () {
        $("video-msg").textContent = "Tap the video to play it.";
        $("video-msg").hidden = false;
      });
    }
  }

  function stopClock() {
    if (playStart !== null) { watchedMs += performance.now() - playStart; playStart = null; }
  }

  video.addEventListener("playing", function () { playStart = performance.now(); $("video-msg").hidden = true; });
  video.addEventListener("pause", stopClock);
  video.addEventListener("ended", function () {
    stopClock();
    $("replay").disabled = false;
    if (trial.phase === "training") { $("continue").disabled = false; }
    else { rateButtons.forEach(function (b) { b.disabled = answered; }); }
  });
  video.addEventListener("click", function () { if (video.paused) { video.play(); } });
  video.addEventListener("error", function () {
    var e = video.error;
    logEvent("video_error", "clip " + (trial && trial.clip_id) + ": code " + (e ? e.code : "?") + " " +
             (e && e.message ? e.message : ""));
    $("video-msg").textContent = "The video could not be played. Press Replay to try again.";
    $("video-msg").hidden = false;
    $("replay").disabled = false;
  });
  var stalledLogged = false;
  video.addEventListener("stalled", function () {
    if (!stalledLogged) { stalledLogged = true; logEvent("video_stalled", "clip " + (trial && trial.clip_id)); }
  });

  function answer(rating) {
    if (answered) { return; }
    answered = true;
    rateButtons.forEach(function (b) { b.disabled = true; });
    $("continue").disabled = true;
    $("replay").disabled = true;
    send(rating, 3);
  }

  // 425: the server counts the clip as not yet played to the end (a slow start); wait as it says, then resend.
  function send(rating, early) {
    api("POST", "/api/sessions/" + token + "/ratings",
        { trial_id: trial.trial_id, rating: rating, watched_ms: Math.round(watchedMs) })
      .then(function (r) {
        if (r.status === 201 || r.status === 200) { next(); }
        else if (r.status === 425 && early > 0) {
          setTimeout(function () { send(rating, early - 1); }, Math.min(r.data.retry_after_ms || 500, 10000));
        }
        else { fail(r.data.error || "the answer was not accepted (" + r.status + ")"); }
      }).catch(function () { answered = false; fail("The server cannot be reached. Please check your connection."); });
  }

  function finish(data) {
    $("completion-code").textContent = data.completion_code;
    show("done");
    if (data.redirect_url) {
      $("redirect-link").href = data.redirect_url;
      $("redirect-msg").hidden = false;
      setTimeout(function () { window.location.assign(data.redirect_url); }, 4000);
    }
  }

  rateButtons.forEach(function (b) {
    b.addEventListener("click", function () { answer(parseInt(b.dataset.rating, 10)); });
  });
  document.addEventListener("keydown", function (ev) {
    if (trial && trial.phase === "rating" && !$("trial").hidden && /^[1-5]$/.test(ev.key) &&
        !rateButtons[0].disabled) { answer(parseInt(ev.key, 10)); }
  });
  $("continue").addEventListener("click", function () { answer(null); });
  $("replay").addEventListener("click", function () {
    $("video-msg").hidden = true;
    if (video.error) { video.load(); }
    video.currentTime = 0;
    video.play();
  });
  $("consent").addEventListener("change", function () { $("start").disabled = !this.checked; });
  $("start").addEventListener("click", start);
  $("intro-go").addEventListener("click", present);
  $("rating-go").addEventListener("click", present);
  $("error-retry").addEventListener("click", function () { window.location.reload(); });
  window.addEventListener("error", function (ev) { logEvent("page_error", ev.message); });

  if (app.dataset.full === "1") { show("full"); return; }
  try { token = sessionStorage.getItem(KEY); } catch (e) { token = null; }
  if (token) { next(); } else { show("welcome"); }
})();
