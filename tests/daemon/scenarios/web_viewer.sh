#!/usr/bin/env bash
# slamd-web with Debian's headless Chromium: a page stays connected while slamd maps a synthetic
# room, slamd restarts, and a page opened after the runs shows the same trail and voxels. Checks
# the counts the page reports against slamd-web's and slamd-pose-log's, the page's own first
# paint measurement, and keeps a screenshot in build/test-output/slamd-web.png.
source "$(dirname "$0")/lib.sh"
private_network
cd "$WORK"
export HOME=$WORK  # Chromium writes its profile and crash folders under $HOME
PORT=8080
URL=http://127.0.0.1:$PORT/
# Debian's /usr/bin/chromium-headless-shell is a script that runs the browser as its child, so
# stopping the script would leave the browser running: start the browser itself.
CHROMIUM_BIN=/usr/lib/chromium/chromium-headless-shell
[ -x "$CHROMIUM_BIN" ] || CHROMIUM_BIN=chromium-headless-shell
CHROMIUM=("$CHROMIUM_BIN" --no-sandbox --enable-unsafe-swiftshader --disable-gpu-sandbox
          --window-size=1280,800 --user-data-dir="$WORK/chromium")

"$SLAMD_BIN/slamd-web" --port $PORT --client-stats-out client-stats.jsonl --log-level info \
  2> web.log &
WEB_PID=$!
http_ok() {
  exec 3<> /dev/tcp/127.0.0.1/$PORT || return 1
  printf 'GET %s HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n' "$1" >&3
  local reply
  reply=$(cat <&3)
  exec 3>&-
  [[ "$reply" == "HTTP/1.1 200"* ]]
}
wait_for 20 "slamd-web to serve its page" http_ok /
for path in /viewer.js /viewer.css /three.min.js /OrbitControls.js; do
  http_ok $path || fail "slamd-web does not serve $path"
done
check "slamd-web serves the page, its script and style, and Debian's three.js"

# A page that stays open through both runs (it reports its measurements back every second).
"${CHROMIUM[@]}" --remote-debugging-port=0 "$URL" > live-page.out 2>&1 &
LIVE_PAGE_PID=$!
wait_for 60 "the live page to report" grep -q first_paint_ms client-stats.jsonl

run_slamd() {
  local frames=$1 log=$2
  "$SLAMD_BIN/slamd" --config "$SLAMD_SOURCE_DIR/config/synthetic.yaml" --log-level warn \
    "${SMALL_CAMERA[@]}" --source synthetic:room --set synthetic.frames="$frames" \
    --set backend.enabled=true 2> "$log" || { tail -20 "$log"; fail "slamd exited with $?"; }
}
# The first run is cut short by a restart the viewer must notice: a second slamd.
run_slamd 90 slamd-1.log
"$SLAMD_BIN/slamd-pose-log" --log-level warn --out poses.txt 2> pose-log.txt &
POSE_LOG_PID=$!
wait_for 10 "slamd-pose-log to open its output" test -e poses.txt
run_slamd 150 slamd-2.log
# The run is over once slamd-pose-log has the second run's poses and the live page has reported
# twice more with the same pose and voxel counts (it reports every second, after slamd-web's
# last 10 Hz tick).
# (A function: the count is read again on every poll, not once when wait_for is called.)
second_run_logged() { [ "$(grep -vc '^#' poses.txt)" -ge 140 ]; }
wait_for 20 "slamd-pose-log to receive the second run's poses" second_run_logged
reports_at_end=$(wc -l < client-stats.jsonl)
live_page_settled() {
  [ "$(wc -l < client-stats.jsonl)" -ge $((reports_at_end + 2)) ] || return 1
  local counts
  counts=$(tail -2 client-stats.jsonl | sed 's/.*"poses_received":\([0-9]*\).*"voxels":\([0-9]*\).*/\1 \2/' | uniq | wc -l)
  [ "$counts" -eq 1 ]
}
wait_for 20 "the live page's counts to settle" live_page_settled
kill -INT $POSE_LOG_PID
wait $POSE_LOG_PID || true
poses_logged=$(grep -vc '^#' poses.txt)
[ "$poses_logged" -ge 140 ] || fail "slamd-pose-log received only $poses_logged poses"

# A page opened now: its counts after it has applied the full state. --virtual-time-budget bounds
# the page's virtual time, and Chromium dumps the DOM when it runs out, whether or not slamd-web's
# full state has arrived over the WebSocket by then: under AddressSanitizer on a loaded machine it
# once had not (CI). Such a dump shows a page still loading, not a wrong one, so the page is
# opened again, up to 6 times.
page_ready() {
  "${CHROMIUM[@]}" --virtual-time-budget=8000 --dump-dom "$URL" > page.html 2> dump.err ||
    fail "headless Chromium could not load $URL: $(tail -3 dump.err)"
  grep -q 'data-ready="1"' page.html
}
attempts=1
until page_ready; do
  [ $attempts -lt 6 ] || fail "the page never applied the full state in $attempts loads: $(head -c 600 page.html)"
  attempts=$((attempts + 1))
done
check "a page opened after the runs applied the full state (load $attempts)"
count() { sed -n "s/.*id=\"$1\"[^>]*>\([0-9][0-9]*\)<.*/\1/p" page.html | head -1; }
page_poses=$(count poses-received)
page_voxels=$(count voxels-shown)
[ -n "$page_poses" ] && [ -n "$page_voxels" ] || fail "the page shows no pose or voxel count"
mkdir -p "$SLAMD_BIN/../test-output"
SCREENSHOT=$SLAMD_BIN/../test-output/slamd-web.png
screenshot_colours() { pngtopnm "$SCREENSHOT" | ppmhist -noheader | wc -l; }
# The same virtual time: a screenshot taken before the full state arrived shows an empty view.
screenshot_shows_the_map() {
  "${CHROMIUM[@]}" --virtual-time-budget=8000 --screenshot="$SCREENSHOT" "$URL" > screenshot.out 2>&1 ||
    fail "no screenshot: $(tail -3 screenshot.out)"
  [ "$(screenshot_colours)" -ge 50 ]
}
attempts=1
until screenshot_shows_the_map; do
  [ $attempts -lt 6 ] || fail "the screenshot has only $(screenshot_colours) colours in $attempts loads: an empty view?"
  attempts=$((attempts + 1))
done

kill -INT $LIVE_PAGE_PID 2> /dev/null || true
kill -INT $WEB_PID
wait $WEB_PID || fail "slamd-web exited with $?: $(tail -5 web.log)"
cat web.log | tail -3
summary=$(grep "poses, " web.log | tail -1)
web_poses=$(echo "$summary" | sed 's/.*slamd-web: \([0-9]*\) poses.*/\1/')
web_voxels=$(echo "$summary" | sed 's/.* \([0-9]*\) occupied voxels.*/\1/')
restarts=$(echo "$summary" | sed 's/.* \([0-9]*\) slamd restarts.*/\1/')

[ "$restarts" -ge 1 ] || fail "slamd-web did not notice the restart: $summary"
check "slamd-web noticed slamd's restart ($summary)"
# The page shows the second run only: what slamd-web kept since the restart.
[ "$page_voxels" -eq "$web_voxels" ] || fail "the page shows $page_voxels voxels, slamd-web holds $web_voxels"
[ "$page_voxels" -ge 500 ] || fail "only $page_voxels voxels of a whole room"
[ "$page_poses" -ge $((poses_logged * 98 / 100)) ] && [ "$page_poses" -le "$poses_logged" ] ||
  fail "the page has $page_poses poses of the second run; slamd-pose-log received $poses_logged"
check "a page opened after the run shows $page_poses poses (slamd-pose-log: $poses_logged) and $page_voxels voxels (slamd-web: $web_voxels)"

last_stats=$(tail -1 client-stats.jsonl)
live_voxels=$(echo "$last_stats" | sed 's/.*"voxels":\([0-9]*\).*/\1/')
[ "$live_voxels" -eq "$web_voxels" ] || fail "the live page ended with $live_voxels voxels, slamd-web holds $web_voxels: $last_stats"
first_paint=$(head -1 client-stats.jsonl | sed 's/.*"first_paint_ms":\([0-9.null]*\).*/\1/')
check "the page that stayed open through both runs ended with the same $live_voxels voxels; its first paint: $first_paint ms"

check "screenshot (build/test-output/slamd-web.png, load $attempts): $(screenshot_colours) colours"
