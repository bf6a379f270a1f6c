// The rater's page: consent -> familiarisation -> rating trials -> completion, all through the JSON API.
// No build step; plain browser JavaScript. One page for every design, which names how its trial is shown
// (data-page, the design's `page` in rating_app/designs/) and its answer's field: acr shows one clip and
// 5 rating buttons; pairwise two clips A and B and 5 preference buttons; parallel a page of clips with a 0-100
// slider each. An answer can be given only once every clip of the trial has played to the end.
(function () {
  "use strict";
  var $ = function (id) { return document.getElementById(id); };
  var app = $("app");
  var sound = app.dataset.sound === "1";  // the videos carry sound: unmuted, started by a tap, after a sound check
  var page = app.dataset.page || "one";  // how a trial is shown: one clip, a pair A/B, or a page of clips
  var answerField = app.dataset.answerField || "rating";  // the design's answer in the API (CONTRACTS §8)
  var question = app.dataset.question || "How natural does this motion look?";
  var KEY = "rating_app_session";
  var token = null;
  var trial = null;          // the trial on screen
  var lastPhase = null;
  var watchedMs = 0, playStart = null, answered = false;
  var video = $("video");
  if (app.dataset.videoWidth) {  // the videos' shape, for the page's wide layout (style.css: .frame-wide)
    document.documentElement.style.setProperty("--video-aspect",
      String(Number(app.dataset.videoWidth) / Number(app.dataset.videoHeight)));
  }
  var rateButtons = Array.prototype.slice.call(document.querySelectorAll("button.rate"));

  function show(id) {
    ["welcome", "audio-check", "audio-failed", "intro", "trial", "pair", "page", "rating-intro", "done", "full",
     "error"].forEach(function (s) {
      $(s).hidden = (s !== id);
    });
    window.scrollTo(0, 0);
  }

  function fail(msg) {
    $("error-msg").textContent = msg;
    show("error");
  }

  // fetch JSON, retrying network errors and 5xx answers (a blip, a server or database restart must not lose the
  // rater) for up to `patience` ms (default RETRY_MS), waiting longer each time and at least what Retry-After asks.
  // Every call the page makes can be repeated safely (an answer is stored once per trial), so retrying one whose
  // reply was lost stores nothing twice. The last 5xx answer, if the time runs out, goes to the caller.
  var RETRY_MS = 120000;
  function api(method, path, body, patience) {
    var until = Date.now() + (patience === undefined ? RETRY_MS : patience);
    var delay = 500;
    var opts = { method: method, headers: { "Accept": "application/json" } };
    if (body !== undefined) {
      opts.headers["Content-Type"] = "application/json";
      opts.body = JSON.stringify(body);
    }
    function reply(r) {
      return r.json().catch(function () { return {}; }).then(function (data) {
        return { status: r.status, data: data };
      });
    }
    function attempt() {
      return fetch(path, opts).then(function (r) {
        if (r.status < 500) { return reply(r); }
        var after = parseFloat(r.headers.get("Retry-After") || "0") * 1000;
        return retry(after, function () { return reply(r); });
      }, function (err) {
        return retry(0, function () { throw err; });
      });
    }
    function retry(after, giveUp) {
      var wait = Math.max(delay, after || 0);
      if (Date.now() + wait > until) { return giveUp(); }
      delay = Math.min(delay * 2, 5000);
      if (patience === undefined) { $("retrying").hidden = false; }
      return new Promise(function (res) { setTimeout(res, wait); }).then(attempt);
    }
    return attempt().then(function (x) {
      if (patience === undefined) { $("retrying").hidden = true; }
      return x;
    }, function (err) {
      if (patience === undefined) { $("retrying").hidden = true; }
      throw err;
    });
  }

  function logEvent(kind, detail) {
    if (!token) { return; }
    api("POST", "/api/sessions/" + token + "/events",
        { kind: kind, detail: String(detail).slice(0, 500), trial_id: trial ? trial.trial_id : null }, 1500)
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
      if (sound) { showAudioCheck(); } else { next(); }
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
      if (r.status === 403 && r.data.audio_check) { showAudioCheck(); return; }
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

  // ---------------------------------------------------------------- the sound check (a study with sound)
  var sample = $("audio-sample");
  function showAudioCheck() {
    $("audio-answer").value = "";
    $("audio-submit").disabled = true;
    sample.src = "/api/sessions/" + token + "/audio-check.wav?t=" + Date.now();
    show("audio-check");
  }
  $("audio-play").addEventListener("click", function () {
    sample.currentTime = 0;
    var p = sample.play();
    if (p && p.catch) { p.catch(function () {}); }
  });
  $("audio-answer").addEventListener("input", function () {
    $("audio-submit").disabled = !/\d/.test($("audio-answer").value);
  });
  $("audio-submit").addEventListener("click", function () {
    $("audio-submit").disabled = true;
    api("POST", "/api/sessions/" + token + "/audio-check", { answer: $("audio-answer").value }).then(function (r) {
      if (r.data.passed) { $("audio-msg").hidden = true; next(); return; }
      if (r.data.final) {
        try { sessionStorage.removeItem(KEY); } catch (e) {}
        $("audio-failed-msg").textContent = r.data.error;
        show("audio-failed");
        return;
      }
      $("audio-msg").textContent = "That did not match. Please listen to this new sample and try once more.";
      $("audio-msg").hidden = false;
      showAudioCheck();
    }).catch(function () { fail("The server cannot be reached. Please check your connection."); });
  });

  // With sound, browsers let a page play only after a tap, so every trial starts from one.
  function startPlaying(videos, msgId) {
    videos.forEach(function (v) { v.muted = !sound; });
    if (sound) {
      $(msgId).textContent = "Tap the video" + (videos.length > 1 ? " A" : "") + " to play it with sound.";
      $(msgId).hidden = false;
      return;
    }
    videos.map(function (v) { return v.play(); }).forEach(function (p) {
      if (p && p.catch) {
        p.catch(function () { $(msgId).textContent = "Tap the video to play it."; $(msgId).hidden = false; });
      }
    });
  }

  function present() {
    if (page === "pair") { presentPair(); return; }
    if (page === "page") { presentPage(); return; }
    lastPhase = trial.phase;
    answered = false;
    watchedMs = 0;
    playStart = null;
    var training = trial.phase === "training";
    $("phase-label").textContent = training ? "Example" : "Video";
    $("trial-count").textContent = trial.index + " of " + trial.of;
    $("question").textContent = training ? "Just watch this example." : question;
    $("buttons").classList.toggle("training", training);
    $("continue").hidden = !training;
    $("continue").disabled = true;
    $("replay").disabled = true;
    $("video-msg").hidden = true;
    rateButtons.forEach(function (b) { b.disabled = true; });
    show("trial");
    video.src = trial.video_url;
    video.load();
    startPlaying([video], "video-msg");
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
  video.addEventListener("click", function () { $("video-msg").hidden = true; if (video.paused) { video.play(); } });
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

  // ---------------------------------------------------------------- pairwise and parallel: several clips
  // Each clip's playing time is added up; `ended` says which clips have played to the end at least once.
  var multi = { videos: [], ended: [], starts: [] };

  function stopMultiClock(i) {
    if (multi.starts[i] !== null && multi.starts[i] !== undefined) {
      watchedMs += performance.now() - multi.starts[i];
      multi.starts[i] = null;
    }
  }

  function watchVideo(v, i, label, onEnded) {
    v.onplaying = function () { multi.starts[i] = performance.now(); };
    v.onpause = function () { stopMultiClock(i); };
    v.onended = function () { stopMultiClock(i); multi.ended[i] = true; onEnded(i); };
    v.onerror = function () {
      var e = v.error;
      logEvent("video_error", "trial " + (trial && trial.trial_id) + " clip " + label + ": code " +
               (e ? e.code : "?") + " " + (e && e.message ? e.message : ""));
    };
  }

  function allEnded() {
    return multi.ended.length > 0 && multi.ended.every(function (x) { return x; });
  }

  function playOnly(i) {
    multi.videos.forEach(function (v, j) { if (j !== i && !v.paused) { v.pause(); } });
    var v = multi.videos[i];
    if (v.ended) { v.currentTime = 0; }
    var p = v.play();
    if (p && p.catch) { p.catch(function () {}); }
  }

  var prefButtons = Array.prototype.slice.call(document.querySelectorAll("button.pref"));

  function presentPair() {
    lastPhase = trial.phase;
    answered = false;
    watchedMs = 0;
    var training = trial.phase === "training";
    var pair = [trial.a, trial.b];
    document.querySelectorAll("#pair .phase-label")[0].textContent = training ? "Example" : "Pair";
    document.querySelectorAll("#pair .trial-count")[0].textContent = trial.index + " of " + trial.of;
    $("pair-question").textContent = training ? "Just watch these examples." : question;
    $("pref-buttons").classList.toggle("training", training);
    $("pair-continue").hidden = !training;
    $("pair-continue").disabled = true;
    $("pair-replay").disabled = true;
    $("pair-msg").hidden = true;
    prefButtons.forEach(function (b) { b.disabled = true; });
    resetReasons(training);
    show("pair");
    // Side by side both play at once; one above the other (a phone) A plays, then B. With sound always one after
    // the other: two voices at once could not be heard.
    var oneAfterOther = sound || window.matchMedia("(max-width: 700px)").matches;
    multi = { videos: [$("video-a"), $("video-b")], ended: [false, false], starts: [null, null] };
    multi.videos.forEach(function (v, i) {
      watchVideo(v, i, i ? "B" : "A", function (j) {
        if (oneAfterOther && j === 0 && !multi.ended[1]) { playOnly(1); }
        if (allEnded()) {
          $("pair-replay").disabled = false;
          if (training) { $("pair-continue").disabled = false; }
          else { prefButtons.forEach(function (b) { b.disabled = answered; }); }
        }
      });
      v.onclick = function () {
        $("pair-msg").hidden = true;
        if (v.paused) { if (oneAfterOther) { playOnly(i); } else { v.play(); } }
      };
      v.src = pair[i].video_url;
      v.load();
    });
    startPlaying(oneAfterOther ? [multi.videos[0]] : multi.videos, "pair-msg");
    multi.videos.forEach(function (v) { v.muted = !sound; });
  }

  function presentPage() {
    lastPhase = trial.phase;
    answered = false;
    watchedMs = 0;
    var training = trial.phase === "training";
    document.querySelectorAll("#page .phase-label")[0].textContent = training ? "Example page" : "Page";
    document.querySelectorAll("#page .trial-count")[0].textContent = trial.index + " of " + trial.of;
    $("page-question").textContent = training ? "Just watch these examples: click each video to play it." : question;
    $("page-submit").textContent = training ? "Next example" : "Submit";
    $("page-submit").disabled = true;
    var box = $("page-clips");
    while (box.firstChild) { box.removeChild(box.firstChild); }
    multi = { videos: [], ended: [], starts: [], sliders: [] };
    trial.clips.forEach(function (c, i) {
      var card = document.createElement("div");
      card.className = "page-clip" + (training ? " training" : "");
      var label = document.createElement("div");
      label.className = "clip-label";
      label.textContent = c.label;
      var player = document.createElement("div");
      player.className = "player";
      var v = document.createElement("video");
      v.muted = !sound;
      v.setAttribute("playsinline", "");
      v.setAttribute("disablepictureinpicture", "");
      v.preload = "auto";
      if (app.dataset.videoWidth) {  // the set's size (manifest): the video keeps its shape before it loads
        v.setAttribute("width", app.dataset.videoWidth);
        v.setAttribute("height", app.dataset.videoHeight);
      }
      v.src = c.video_url;
      player.appendChild(v);
      var slider = document.createElement("input");
      slider.type = "range";
      slider.min = "0";
      slider.max = "100";
      slider.step = "1";
      slider.value = "50";
      slider.disabled = true;
      slider.setAttribute("aria-label", "Rating of " + c.label + ", 0 to 100");
      slider.dataset.clipId = c.clip_id;
      var value = document.createElement("div");
      value.className = "value";
      value.textContent = "50";
      slider.addEventListener("input", function () { value.textContent = slider.value; });
      card.appendChild(label);
      card.appendChild(player);
      card.appendChild(slider);
      card.appendChild(value);
      box.appendChild(card);
      multi.videos.push(v);
      multi.ended.push(false);
      multi.starts.push(null);
      multi.sliders.push(slider);
      watchVideo(v, i, c.label, function (j) {
        multi.sliders[j].disabled = answered;
        updatePageState();
      });
      v.addEventListener("play", function () { card.classList.add("playing"); });
      v.addEventListener("pause", function () { card.classList.remove("playing"); });
      v.addEventListener("click", function () { playOnly(i); });
    });
    updatePageState();
    show("page");
  }

  function updatePageState() {
    var left = multi.ended.filter(function (x) { return !x; }).length;
    $("page-left").textContent = left ? left + " video" + (left > 1 ? "s" : "") + " still to play to the end" : "";
    $("page-submit").disabled = answered || left > 0;
  }

  function answerMulti(value) {
    if (answered) { return; }
    answered = true;
    prefButtons.forEach(function (b) { b.disabled = true; });
    $("pair-continue").disabled = true;
    $("page-submit").disabled = true;
    (multi.sliders || []).forEach(function (s) { s.disabled = true; });
    multi.videos.forEach(function (v, i) { stopMultiClock(i); });
    send(value, 3);
  }

  // The reasons shown with a pairwise vote (optional): ticked before the preference, sent with it.
  var reasonBox = $("reasons");
  // The free text is counted in characters (code points), as the server counts it (Python's len), not in the
  // UTF-16 units of maxlength, which count an emoji twice: the page keeps the first data-max-chars characters.
  var reasonText = $("reason-text");
  function keepChars() {
    var max = parseInt(reasonText.dataset.maxChars, 10);
    var chars = Array.from(reasonText.value);
    if (chars.length > max) { chars = chars.slice(0, max); reasonText.value = chars.join(""); }
    $("reason-count").textContent = chars.length + " / " + max + " characters";
  }
  if (reasonText) { reasonText.addEventListener("input", keepChars); }
  function resetReasons(training) {
    if (!reasonBox) { return; }
    reasonBox.hidden = training;
    reasonBox.querySelectorAll("input[name=reason]").forEach(function (x) { x.checked = false; });
    if (reasonText) { reasonText.value = ""; keepChars(); }
  }
  function reasonFields(body) {
    if (!reasonBox || trial.phase === "training") { return; }
    body.reasons = Array.prototype.slice.call(reasonBox.querySelectorAll("input[name=reason]:checked"))
      .map(function (x) { return x.value; });
    if ($("reason-text") && $("reason-text").value) { body.reason_text = $("reason-text").value; }
  }

  prefButtons.forEach(function (b) {
    b.addEventListener("click", function () { answerMulti(parseInt(b.dataset.preference, 10)); });
  });
  $("pair-continue").addEventListener("click", function () { answerMulti(null); });
  $("pair-replay").addEventListener("click", function () {
    var oneAfterOther = sound || window.matchMedia("(max-width: 700px)").matches;
    multi.videos.forEach(function (v) { v.currentTime = 0; });
    if (oneAfterOther) { playOnly(0); } else { multi.videos.forEach(function (v) { v.play(); }); }
  });
  $("page-submit").addEventListener("click", function () {
    if (trial.phase === "training") { answerMulti(null); return; }
    var ratings = {};
    multi.sliders.forEach(function (s) { ratings[s.dataset.clipId] = parseInt(s.value, 10); });
    answerMulti(ratings);
  });

  // 425: the server counts the clip as not yet played to the end (a slow start); wait as it says, then resend.
  function send(rating, early) {
    var body = { trial_id: trial.trial_id, watched_ms: Math.round(watchedMs) };
    body[answerField] = rating;
    if (page === "pair") { reasonFields(body); }
    api("POST", "/api/sessions/" + token + "/ratings", body)
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
