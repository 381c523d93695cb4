-- Mixed load for wrk: level fetches, level choices, bake submissions and uploads, by weight.
-- Reads its targets from the environment (set by bench/load/run.sh):
--   LOAD_LEVELS   space-separated /v1/levels/{hash} paths
--   LOAD_BAKES    space-separated bake ids
--   LOAD_CHARACTER  the character id;  LOAD_SAMPLE  the file uploaded
-- Each thread counts the requests it sends by kind and the responses by status (wrk does
-- not say which request a response answers); done() prints "SENT kind n" and
-- "STATUS code n" lines and one RESULT line with the latency percentiles.
local threads = {}

function setup(thread)
  table.insert(threads, thread)
end

local function split(text)
  local items = {}
  for item in string.gmatch(text or "", "%S+") do table.insert(items, item) end
  return items
end

function init(args)
  levels = split(os.getenv("LOAD_LEVELS"))
  bakes = split(os.getenv("LOAD_BAKES"))
  character = os.getenv("LOAD_CHARACTER")
  local file = io.open(os.getenv("LOAD_SAMPLE"), "rb")
  sample = file:read("*all")
  file:close()
  sent = {}
  statuses = {}
  math.randomseed(os.time() + math.floor(os.clock() * 1e6))
end

-- Weights out of 1000: 900 level fetches, 60 level choices, 30 bakes, 10 uploads.
local function count(kind)
  sent[kind] = (sent[kind] or 0) + 1
end

function request()
  local roll = math.random(1000)
  if roll <= 900 then
    count("level")
    return wrk.format("GET", levels[math.random(#levels)])
  elseif roll <= 960 then
    count("choice")
    return wrk.format("GET", "/v1/bakes/" .. bakes[math.random(#bakes)] .. "/level?px=" ..
                      math.random(20, 400), {["Accept"] = "application/json"})
  elseif roll <= 990 then
    -- Levels and fps drawn from a small set: some bakes are new (202, or 503 when the
    -- queue is full), most were asked for before (200).
    count("bake")
    local body = string.format('{"character":"%s","motion":"Walking_A","levels":[%d,6],"fps":%d}',
                               character, math.random(7, 17), 10 * math.random(1, 3))
    return wrk.format("POST", "/v1/bakes", {["Content-Type"] = "application/json"}, body)
  else
    count("upload")
    return wrk.format("POST", "/v1/characters?filename=load.glb",
                      {["Content-Type"] = "application/octet-stream"}, sample)
  end
end

function response(status, headers, body)
  statuses[status] = (statuses[status] or 0) + 1
end

function done(summary, latency, requests)
  for _, name in ipairs({"sent", "statuses"}) do
    local total = {}
    for _, thread in ipairs(threads) do
      for key, n in pairs(thread:get(name)) do total[key] = (total[key] or 0) + n end
    end
    for key, n in pairs(total) do
      io.write(string.format("%s %s %d\n", name == "sent" and "SENT" or "STATUS", key, n))
    end
  end
  local seconds = summary.duration / 1e6
  local errors = summary.errors.connect + summary.errors.read + summary.errors.write +
                 summary.errors.timeout
  io.write(string.format("RESULT requests=%d seconds=%.2f rps=%.0f p50_ms=%.3f p90_ms=%.3f p99_ms=%.3f max_ms=%.3f socket_errors=%d\n",
    summary.requests, seconds, summary.requests / seconds,
    latency:percentile(50) / 1000, latency:percentile(90) / 1000, latency:percentile(99) / 1000,
    latency.max / 1000, errors))
end
