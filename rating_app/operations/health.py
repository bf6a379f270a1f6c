"""What the app notices about how it is set up, and says: a catch pool too small for the share of raters a test unit
reaches (then the clips two sessions share point at the catch trials), and a reverse proxy in front that PROXY_COUNT
does not trust (then every rater has the proxy's address, and the per-client limits hold for the whole study).

Each warning is logged once per process and listed on the dashboard, in progress.json and in GET /healthz
(`"warnings"`); none of them stops the app. The proxy is noticed per request, so a worker says so from the first
request that came through it (the admin's own dashboard request, behind that proxy, included).
"""

from __future__ import annotations

import ipaddress
import math
import threading

from flask import current_app, request

from ..designs import get
from ..pairing.assign import n_catch_slots

FAIR_RATIO = 1.5  # a catch unit may reach at most this many times the share of raters a test unit reaches


class Warnings:
    """The app's warnings, by key; each is logged when first added."""

    def __init__(self, logger):
        self.logger, self.items, self.lock = logger, {}, threading.Lock()

    def add(self, key: str, message: str) -> None:
        with self.lock:
            if key in self.items:
                return
            self.items[key] = message
        self.logger.warning("warning: %s", message)

    def list(self) -> list[str]:
        return list(self.items.values())


def of_app(app=None) -> Warnings:
    return (app or current_app).extensions["rating_app"]["warnings"]


def catch_pool_warning(design, clips, units, clips_per_rater, catch_per_rater) -> str | None:
    """A line when each catch unit would reach more than FAIR_RATIO times the share of raters a test unit does."""
    n_test, pool = get(design).pool(clips, units)
    if not n_test or not pool:
        return None
    per_rater = min(clips_per_rater or n_test, n_test)
    test_share, n_catch = per_rater / n_test, n_catch_slots(pool, catch_per_rater)
    catch_share = n_catch / pool
    if catch_share <= FAIR_RATIO * test_share:
        return None
    need = math.ceil(n_catch * n_test / per_rater)
    return (
        f"catch pool too small: each of the {pool} catch units reaches {catch_share:.0%} of the raters, a test unit "
        f"{test_share:.0%}, so the clips two sessions share point at the catch trials. Make about {need} catch "
        f"units (e.g. more catch items in generation.make_stimuli) or lower RATING_CATCH_PER_RATER ({n_catch} now)"
    )


def _local(addr: str | None) -> bool:
    """A loopback or private peer (a unix socket has no address: local too)."""
    if not addr:
        return True
    try:
        ip = ipaddress.ip_address(addr)
    except ValueError:
        return False
    if ip.version == 6 and ip.ipv4_mapped is not None:
        ip = ip.ipv4_mapped
    return ip.is_loopback or ip.is_private


def note_untrusted_proxy() -> None:
    """before_request: a request from a loopback or private peer that carries X-Forwarded-For while PROXY_COUNT is 0
    came through a reverse proxy the app does not trust."""
    if current_app.config["PROXY_COUNT"] or "X-Forwarded-For" not in request.headers:
        return
    peer = request.remote_addr
    if _local(peer):
        of_app().add(
            "proxy",
            f"requests come through a reverse proxy (X-Forwarded-For, from {peer or 'a unix socket'}) but "
            "RATING_PROXY_COUNT is 0: every rater has the proxy's address, so RATING_SESSIONS_PER_CLIENT and the "
            "admin lockout count all raters as one client. Set RATING_PROXY_COUNT to the number of proxies in front "
            "of the app",
        )
