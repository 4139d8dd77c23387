package iristk.system;

import java.util.LinkedHashMap;
import java.util.Map;

/** Stand-in for IrisTK's Event: what Broker.removeClient uses (a name, string fields, toJSON) (pairplay test stub). */
public class Event {
    private final String name;
    private final Map<String, String> fields = new LinkedHashMap<>();

    public Event(String name) { this.name = name; }

    public void put(String key, Object value) { fields.put(key, String.valueOf(value)); }

    public String getName() { return name; }

    public Object toJSON() {
        StringBuilder json = new StringBuilder("{\"class\":\"iristk.system.Event\",\"event_name\":\"" + name + "\"");
        for (Map.Entry<String, String> field : fields.entrySet()) {
            json.append(",\"").append(field.getKey()).append("\":\"").append(field.getValue()).append("\"");
        }
        return json.append("}").toString();
    }
}
