"""Reverse-proxy configurations for the tests and benches that put nginx or Caddy in front of the app: the parts
they share, so that each test writes only its own server block."""

import os


def nginx_head(tmp):
    """The top of an nginx.conf run in the foreground with every file in `tmp`. As root (CI), the workers stay
    root: dropped to nobody they could not read the tests' private temp folders."""
    user = "user root;" if os.geteuid() == 0 else ""
    return f"""{user}
worker_processes 1;
daemon off;
pid {tmp}/nginx.pid;
error_log {tmp}/nginx-error.log;
events {{ worker_connections 1024; }}
"""


def nginx_temp_paths(tmp):
    return (
        f"client_body_temp_path {tmp}/body; proxy_temp_path {tmp}/proxy; fastcgi_temp_path {tmp}/fastcgi;\n"
        f"  uwsgi_temp_path {tmp}/uwsgi; scgi_temp_path {tmp}/scgi;"
    )


def nginx_accel(stimuli):
    """nginx's internal location for VIDEO_ACCEL=nginx (CONTRACTS §5): the stimulus folder, no ETag, no date."""
    return f"""location /_stimuli/ {{
      internal;
      alias {stimuli}/;
      types {{ video/mp4 mp4; }}
      etag off;
      add_header Last-Modified "" always;
      add_header Cache-Control "private, max-age=3600" always;
    }}"""


def caddy_accel(stimuli):
    """Caddy's handle_response for VIDEO_ACCEL=caddy, inside a reverse_proxy block (deploy/Caddyfile)."""
    return f"""@accel header X-Accel-Redirect *
    handle_response @accel {{
      root * {stimuli}
      rewrite * {{rp.header.X-Accel-Redirect}}
      uri strip_prefix /_stimuli
      header -Last-Modified
      header -Etag
      header Cache-Control "private, max-age=3600"
      file_server
    }}"""
