// An OPC UA client of another stack than the gateway's (node-opcua), run as its own process
// by tests/opcua/test_node_client.py: node client.js <endpoint>.
// It says what it saw as one JSON object per line on stdout ({"step": ...}); it waits for a
// line "fault" on stdin before it waits for the alarm (the test injects the fault then).
"use strict";
const readline = require("readline");
const {
  OPCUAClient, MessageSecurityMode, SecurityPolicy, AttributeIds, DataType,
  ClientSubscription, ClientMonitoredItem, TimestampsToReturn, constructEventFilter,
  ReadEventDetails, HistoryReadRequest,
} = require("node-opcua-client");

const endpoint = process.argv[2];
const say = (step, data) => process.stdout.write(JSON.stringify({ step, ...data }) + "\n");
const lines = readline.createInterface({ input: process.stdin });
const nextLine = () => new Promise((resolve) => lines.once("line", resolve));

function until(what, predicate, ms) {
  return new Promise((resolve, reject) => {
    const timer = setTimeout(() => reject(new Error("timed out waiting for " + what)), ms);
    const poll = () => {
      const found = predicate();
      if (found) { clearTimeout(timer); resolve(found); } else { setTimeout(poll, 20); }
    };
    poll();
  });
}

async function call(session, drive, method, args) {
  const result = await session.call({
    objectId: `ns=2;s=${drive}`,
    methodId: `ns=2;s=${drive}.${method}`,
    inputArguments: args || [],
  });
  const out = result.outputArguments && result.outputArguments[0];
  return { status: result.statusCode.name, text: out ? out.value : null };
}

async function main() {
  const timeout = Number(process.env.CLIENT_TIMEOUT_MS || 30000);
  const client = OPCUAClient.create({
    applicationName: "drive-gateway-node-test",
    endpointMustExist: false,
    securityMode: MessageSecurityMode.None,
    securityPolicy: SecurityPolicy.None,
    connectionStrategy: { maxRetry: 3, initialDelay: 200, maxDelay: 1000 },
  });
  await client.connect(endpoint);
  const session = await client.createSession();

  const drives = await session.browse("ns=2;s=Drives");
  const m1 = await session.browse("ns=2;s=m1");
  say("browsed", {
    drives: drives.references.map((r) => r.browseName.name).sort(),
    m1: m1.references.map((r) => r.browseName.name),
  });

  const device = await session.read({ nodeId: "ns=2;s=m1.Device", attributeId: AttributeIds.Value });
  const units = await session.read({ nodeId: "ns=2;s=m1.SpeedRpm.EngineeringUnits", attributeId: AttributeIds.Value });
  say("read", { device: device.value.value, unitId: units.value.value.unitId, unit: units.value.value.displayName.text });

  const subscription = ClientSubscription.create(session, {
    requestedPublishingInterval: 100, requestedLifetimeCount: 100, requestedMaxKeepAliveCount: 10,
    maxNotificationsPerPublish: 100, publishingEnabled: true, priority: 1,
  });
  const running = [];
  const item = ClientMonitoredItem.create(
    subscription, { nodeId: "ns=2;s=m1.Running", attributeId: AttributeIds.Value },
    { samplingInterval: 100, discardOldest: true, queueSize: 10 }, TimestampsToReturn.Both,
  );
  item.on("changed", (dv) => running.push(dv.value.value));
  const events = [];
  const fields = ["EventId", "SourceName", "Message", "Severity", "Retain"];
  const alarms = ClientMonitoredItem.create(
    subscription, { nodeId: "ns=0;i=2253", attributeId: AttributeIds.EventNotifier },
    { queueSize: 100, discardOldest: true, filter: constructEventFilter(fields) }, TimestampsToReturn.Both,
  );
  alarms.on("changed", (values) => {
    const event = {};
    fields.forEach((name, i) => { event[name] = values[i].value; });
    events.push(event);
  });
  await until("the first Running value", () => running.length > 0, timeout);

  const speed = await call(session, "m1", "SetSpeed", [{ dataType: DataType.Double, value: 600 }]);
  const run = await call(session, "m1", "Run");
  await until("Running true", () => running.includes(true), timeout);
  const refused = await call(session, "m2", "Run");
  const stop = await call(session, "m1", "Stop");
  await until("Running false after the stop", () => running[running.length - 1] === false, timeout);
  say("commands", { speed, run, refused, stop });

  const history = await session.readHistoryValue(
    "ns=2;s=m1.SpeedRpm", new Date(1700000010 * 1000), new Date(1700000019 * 1000),
  );
  say("history", {
    status: history.statusCode.name,
    values: history.historyData.dataValues.map((dv) => dv.value.value),
  });

  const historyFields = ["EventId", "SourceName", "Time", "Message", "Severity"];
  const eventHistory = await session.historyRead(new HistoryReadRequest({
    historyReadDetails: new ReadEventDetails({
      startTime: new Date(1700000010 * 1000),
      endTime: new Date(1700000015 * 1000),
      numValuesPerNode: 0,
      filter: constructEventFilter(historyFields),
    }),
    nodesToRead: [{ nodeId: "ns=2;s=m1" }],
    timestampsToReturn: TimestampsToReturn.Both,
  }));
  const read = eventHistory.results[0];
  say("event_history", {
    status: read.statusCode.name,
    events: read.historyData.events.map((e) => ({
      source: e.eventFields[1].value,
      message: e.eventFields[3].value.text,
      severity: e.eventFields[4].value,
    })),
  });

  say("waiting_alarm", {});
  await nextLine();
  const raised = await until("the fault alarm", () => events.find((e) => e.Retain === true), timeout);
  const refusedRun = await call(session, "m1", "Run");
  const ack = await session.call({
    objectId: "ns=2;s=m1.FaultAlarm",
    methodId: "ns=0;i=9111",
    inputArguments: [
      { dataType: DataType.ByteString, value: raised.EventId },
      { dataType: DataType.LocalizedText, value: { text: "seen by node-opcua" } },
    ],
  });
  const again = await session.call({
    objectId: "ns=2;s=m1.FaultAlarm",
    methodId: "ns=0;i=9111",
    inputArguments: [
      { dataType: DataType.ByteString, value: raised.EventId },
      { dataType: DataType.LocalizedText, value: { text: "twice" } },
    ],
  });
  await until("the acknowledged event", () => events.length >= 2, timeout);
  say("alarm", {
    message: raised.Message.text, severity: raised.Severity, source: raised.SourceName,
    refusedRun, ack: ack.statusCode.name, again: again.statusCode.name,
  });

  await subscription.terminate();
  await session.close();
  await client.disconnect();
  say("done", {});
  lines.close();
}

main().catch((err) => {
  say("error", { message: String(err && err.stack ? err.stack : err) });
  process.exit(1);
});
